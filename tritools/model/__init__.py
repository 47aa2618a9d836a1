"""tritools.model."""
