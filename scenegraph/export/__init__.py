"""Output: the USD stage, BVH export and preview pictures."""
