"""The world state of a scenario: the Scene (characters, styles, ground, footsteps), the goal and
coupling records (``goals/``) and the measures they report."""
