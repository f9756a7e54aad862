"""grindtwin online: the scene's estimator, NMPC and soft sensor against a live plant over OPC UA
(``grindtwin serve``, :class:`Service`), and the scene's plant twin behind an OPC UA server as a
virtual plant (``grindtwin plant-server``, :class:`PlantServer`). Needs the ``online`` extra
(asyncua); tag maps: :mod:`scenarios.online.tags`; security: :mod:`scenarios.online.security`."""

from pathlib import Path

from scenarios.online.audit import AuditLog, check_audit_dir, read_audit
from scenarios.online.clock import Clock, ManualClock
from scenarios.online.lock_step import run_lock_step
from scenarios.online.opcua import CONNECTION_ERRORS, PlantConnection
from scenarios.online.parts import ControlParts, build_parts, run_in_process
from scenarios.online.plant_server import FAULTS, PlantServer, PlantServerSettings
from scenarios.online.quality import Reading, TagQuality, Verdict, severity
from scenarios.online.security import (PASSWORD_ENV, ClientSecurity, ServerSecurity, hash_password, make_certificate,
                                       read_password)
from scenarios.online.service import ServeSettings, Service
from scenarios.online.soft_sensor import SoftPrediction, SoftSensor
from scenarios.online.tags import TagMap, TagMapError, load_tags
from scenarios.online.writer import Limit, limit_move

#: The tag map of the virtual plant for scenes with ores B and D (the reference transition).
VIRTUAL_PLANT_TAGS = Path(__file__).parent / "data" / "virtual_plant_tags.toml"

__all__ = ["AuditLog", "CONNECTION_ERRORS", "ClientSecurity", "Clock", "ControlParts", "FAULTS", "Limit",
           "ManualClock", "PASSWORD_ENV", "PlantConnection", "PlantServer", "PlantServerSettings", "Reading",
           "ServeSettings", "ServerSecurity", "Service", "SoftPrediction", "SoftSensor", "TagMap", "TagMapError",
           "TagQuality", "VIRTUAL_PLANT_TAGS", "Verdict", "build_parts", "check_audit_dir", "hash_password", "limit_move", "load_tags",
           "make_certificate", "read_audit", "read_password", "run_in_process", "run_lock_step", "severity"]
