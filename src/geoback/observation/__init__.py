"""Observation: instruments as observation operators (x = P u - G c, eqns 9-26) and readings matched to
their stations."""
