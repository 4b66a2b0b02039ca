"""The scenario language: schema, safe YAML loading with source locations, bundled files."""
from scenarios.errors import ComposeError, InputError, Location
from scenarios.schema import Scenario, FieldProblem, BODY_PRESETS, HANDLE_NAMES, JOINT_DOF_NAMES, JOINT_NAMES, SCHEDULE_KINDS
from scenarios.bundled import BUNDLED_DIR, STYLES_DIR, bundled_scenarios, bundled_styles, find_scenario, resolve_style
from scenarios.loader import load_scenario, parse_scenario, validate_scenario, scenario_json_schema

__all__ = ["ComposeError", "InputError", "Location",
           "Scenario", "FieldProblem", "BODY_PRESETS", "HANDLE_NAMES", "JOINT_DOF_NAMES", "JOINT_NAMES",
           "SCHEDULE_KINDS", "BUNDLED_DIR", "STYLES_DIR", "bundled_scenarios", "bundled_styles", "find_scenario",
           "resolve_style", "load_scenario", "parse_scenario", "validate_scenario", "scenario_json_schema"]
