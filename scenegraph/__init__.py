"""The world and its physics: character model, style, motion, dynamics, spacetime, export."""
from scenegraph.model.body import Character, make_character, standing_pose, PRESETS, DOF_NAMES, JOINT_DOF_NAMES, N_DOF
from scenegraph.model.style import Style, default_style, load_style, save_style

__all__ = ["Character", "make_character", "standing_pose", "PRESETS", "DOF_NAMES", "JOINT_DOF_NAMES", "N_DOF",
           "Style", "default_style", "load_style", "save_style"]
