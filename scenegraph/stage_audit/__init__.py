"""An independent physics audit of any UsdSkel stage (``compose audit``).

It reads only the stage — joint transforms and skinned meshes through UsdSkel, mass from
``UsdPhysics.MassAPI`` or the meshes' volumes — never compose's dynamics, transcription or
residual kernels (tests/system/test_architecture.py enforces it): it is the check of them.
See docs/audit.md for what is measured and the tolerances.
"""
from scenegraph.stage_audit.reader import DEFAULT_DENSITY, read_stage
from scenegraph.stage_audit.verdict import (SUMMARY_KEYS, AuditSettings, Tolerances, audit_samples, audit_stage,
                                            summary_line)

__all__ = ["audit_stage", "audit_samples", "read_stage", "AuditSettings", "Tolerances", "SUMMARY_KEYS", "summary_line",
           "DEFAULT_DENSITY"]
