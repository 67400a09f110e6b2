"""The robot's own geometry: identification, identifiability, observability, stated accuracy."""
