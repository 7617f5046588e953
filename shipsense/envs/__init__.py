"""Gymnasium environments of ship passages past a sensor array (shared/spec/design.md section 4)."""
