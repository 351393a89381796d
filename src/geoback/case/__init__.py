"""The case: the YAML file, its schema and every check that needs no finite elements (geometry,
construction, strength, the stated measurement covariance, the mesh size known before gmsh runs)."""
