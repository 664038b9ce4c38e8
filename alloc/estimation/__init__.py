"""Estimation, detection and identifiable allocation (seed section 1.3.1-1.3.2)."""
