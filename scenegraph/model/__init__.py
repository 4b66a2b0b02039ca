"""The character model and its physics: body, kinematics, dynamics and the per-point residual,
compiled kernels, style parameters, ground, footsteps, gait initialisation, motion splines,
and the physics audit of a motion."""
