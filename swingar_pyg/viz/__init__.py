"""Pictures of bodies and garments (needs the viz extra: matplotlib)."""
