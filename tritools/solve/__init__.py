"""tritools.solve."""
