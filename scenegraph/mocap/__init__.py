"""Motion capture in: BVH parsing, retargeting onto the character, clips and footstep contacts."""
