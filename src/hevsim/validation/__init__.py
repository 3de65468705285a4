"""Validation of hevsim against measured data (EPA label figures, the EPA Test Car List)."""
