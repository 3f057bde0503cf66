"""Web API: the REST routes, probes, metrics and the loop-health web page (FastAPI); reads the
store and never computes a diagnosis."""
