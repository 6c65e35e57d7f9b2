"""Rig design by gradient: an explicit, differentiable model of a rig's uncertainty and coverage.

``params``: the continuous design parameters, their bounds and the rig (TOML) of a design.
``model``: the Dr.Jit forward model (stripe images, sensitivity, noise, circle fit, smooth
coverage) with reverse-mode gradients.  ``optimize``: multi-start L-BFGS-B seeded by a grid of
the model, the report.  ``maps``: two-parameter maps.  Imports ``scenes`` and ``geometry`` only.
"""
