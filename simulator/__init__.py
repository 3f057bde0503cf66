"""Closed-loop plant simulation: process, PI controller, sticky valve (pure numpy)."""
