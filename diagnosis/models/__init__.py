"""Data files the diagnosis ships: ``cause_model.npz``, the learned decision (issue 46), and
``rice_envelope.npz``, the Rice envelope's mean that ``cause_split`` reads."""
