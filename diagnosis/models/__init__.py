"""Model files the diagnosis ships (``cause_model.npz``: the learned decision, issue 46)."""
