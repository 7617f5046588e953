"""Array design: Fisher information, observability and ambiguity, sensor placement (shared/spec/design.md)."""
