"""Elastoplastic (Mohr-Coulomb) forward model of an excavation, with exact sensitivities.

* :mod:`.mohr_coulomb` - vectorised, complex-safe return mapping and consistent tangent;
* :mod:`.incremental` - incremental Newton solution of the excavation and direct
  differentiation (``solve``, ``Options``, ``ParameterDerivative``, ``Result``);
* :mod:`.closed_form` - deep circular tunnel (Salencon 1969; Carranza-Torres & Fairhurst 2000);
* :mod:`.operators` - quadrature-point operators of an ``FEModel``;
* :mod:`.linear` - unsymmetric sparse factorisation with counters.
"""
from geoback.physics.plasticity.closed_form import DeepTunnelMC
from geoback.physics.plasticity.incremental import NonConvergence, Options, ParameterDerivative, Result, solve
from geoback.physics.plasticity.mohr_coulomb import Material

__all__ = ["DeepTunnelMC", "Material", "NonConvergence", "Options", "ParameterDerivative", "Result", "solve"]
