"""Worth: forecasts with their bands, data worth of candidate instruments and discrimination between
hypotheses, from the linear analysis of a fit."""
