"""Physics behind one interface: the `Simulation` protocol and its value types, the mesh, FE operators,
solver, ground, every simulation (one-step elastic, staged with a lining, Mohr-Coulomb) and the extension
table; `physics.factory.make_simulation` builds the one a case needs."""
