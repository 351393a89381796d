"""The case: the YAML file, its schema and every check that needs no finite elements (geometry,
construction, strength, the stated measurement covariance, the mesh size known before gmsh runs) and
the limits of the work a case may ask for: the size limit (``meshsize``) and the time limit with the
progress lines of long runs (``budget``)."""
