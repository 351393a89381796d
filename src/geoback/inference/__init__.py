"""Inference: parameters, the misfit seam, error scales, the estimate (Gauss-Newton / Levenberg-Marquardt),
its reliability (eqns 43-55), profile likelihood, identification and replicates."""
