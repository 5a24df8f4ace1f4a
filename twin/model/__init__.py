"""The common model space (paper §2, §3.8) and what fills it: the partial models' ports, parameters (one address
each, with its unit and change cost) and relations; the control model, the Python reference of the firmware's C
(Eqs. 8–11); tracks; a catalogue motor put on a twin; parameter files."""

from twin.model.control import ControlParams, FirmwareState
from twin.model.environment import load_track
from twin.model.motor_setup import MOTOR_MODEL, catalogue_motor, motor_for_robot, use_motor
from twin.model.parameter_files import load_gains, load_values, save_values
from twin.model.partial_models import default_space
from twin.model.space import ChangeCost, ModelSpace, Parameter, PartialModel, Port, Relation

__all__ = ["MOTOR_MODEL", "ChangeCost", "ControlParams", "FirmwareState", "ModelSpace", "Parameter", "PartialModel",
           "Port", "Relation", "catalogue_motor", "default_space", "load_gains", "load_track", "load_values",
           "motor_for_robot", "save_values", "use_motor"]
