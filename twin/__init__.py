"""The digital twin: the common model space, the environment, the world build, the closed loop in C, and the
command line (:mod:`twin.cli`).

Importing ``twin`` loads nothing heavy, so ``python -m twin.run`` can handle Ctrl-C from its first instant; the
names below load on first use.
"""

__all__ = ["ChangeCost", "DigitalTwin", "ModelSpace", "TwinError"]


def __getattr__(name: str):
    if name == "DigitalTwin":
        from twin.digital_twin import DigitalTwin

        return DigitalTwin
    if name in ("ChangeCost", "ModelSpace"):
        from twin import model_space

        return getattr(model_space, name)
    if name == "TwinError":
        from twin.errors import TwinError

        return TwinError
    raise AttributeError(f"module 'twin' has no attribute {name!r}")
