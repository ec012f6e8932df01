"""Pose optimisers behind one interface: ISA (default), APF, PF, FSA, ICP.

`make_optimizer(name, space, **kwargs)` builds one by name. Modules are imported on demand, so a
missing or broken optimiser module only affects that optimiser. The ICP module (icp.py) registers
by defining an Optimizer subclass whose `name` is "icp".
"""
from __future__ import annotations

import importlib

from ..errors import InputError
from .base import DEFAULT_BUDGET, EnergyFn, EnergyOutputError, FrameResult, Optimizer, OptimizerInputError, PoseSpace

DEFAULT_OPTIMIZER = "isa"

# name -> module holding an Optimizer subclass with that `name`
_REGISTRY = {
    "isa": "isa",
    "apf": "apf",
    "pf": "pf",
    "fsa": "fsa",
    "icp": "icp",
}


class UnknownOptimizerError(InputError):
    """The requested optimiser name is not registered or its module is missing."""


def available_optimizers() -> list[str]:
    return list(_REGISTRY)


def optimizer_class(name: str) -> type[Optimizer]:
    key = str(name).strip().lower()
    if key not in _REGISTRY:
        raise UnknownOptimizerError(f"unknown optimiser {name!r}: choose one of {', '.join(_REGISTRY)}")
    try:
        module = importlib.import_module(f".{_REGISTRY[key]}", __name__)
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{_REGISTRY[key]}":
            raise
        raise UnknownOptimizerError(f"optimiser {key!r} is registered but core/optimizers/{_REGISTRY[key]}.py "
                                    f"is not installed yet: use one of isa, apf, pf, fsa") from exc
    for value in vars(module).values():
        if isinstance(value, type) and issubclass(value, Optimizer) and getattr(value, "name", None) == key:
            return value
    raise UnknownOptimizerError(f"core/optimizers/{_REGISTRY[key]}.py defines no Optimizer subclass "
                                f"with name = {key!r}")


def make_optimizer(name: str, space: PoseSpace, **kwargs) -> Optimizer:
    """Build an optimiser by name ("isa" | "apf" | "pf" | "fsa" | "icp"); kwargs go to its constructor
    (budget, seed and the algorithm's own parameters)."""
    return optimizer_class(name)(space, **kwargs)


__all__ = ["DEFAULT_BUDGET", "DEFAULT_OPTIMIZER", "EnergyFn", "EnergyOutputError", "FrameResult", "Optimizer",
           "OptimizerInputError", "PoseSpace", "UnknownOptimizerError", "available_optimizers", "make_optimizer",
           "optimizer_class"]
