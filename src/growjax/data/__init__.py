"""Data: experiment files, experiment sets and their manifests, the shipped and public data sets, synthetic
data."""
