"""The digital twin: the common model space, the environment, the world build and the command line."""

from twin.digital_twin import DigitalTwin
from twin.errors import TwinError
from twin.model_space import ChangeCost, ModelSpace

__all__ = ["DigitalTwin", "TwinError", "ChangeCost", "ModelSpace"]
