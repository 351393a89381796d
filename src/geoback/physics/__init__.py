"""Physics behind one interface: the `Simulation` protocol and its value types, the mesh, FE operators,
solver, ground, every simulation (one-step elastic, staged with a lining, Mohr-Coulomb) and the extension
table. Simulations are composed, not inherited: each holds a `domain.Domain` (built once by
`build_domain`), a `names.Names` resolver and its own components (`stiffness.FactorCache`,
`lined_system.LinedSystem`, the plastic run memo); `physics.factory.make_simulation` builds the one a
case needs from the registry `factory.IMPLEMENTATIONS`."""
