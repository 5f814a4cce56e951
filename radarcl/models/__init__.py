"""Evidence models, one table: ``MODELS`` {name: ``base.EvidenceModel``}, the values of
``interpret.model``. Everything that differs between models (their keys, the channels their maps
carry, their kernel switches and device tables, how a map of them is read, their oracle) is an
attribute or method of the model; no code outside this package asks which model is in force.

Adding one: a class in its own module here (or anywhere) and ``register(TheModel())``; see
docs/design/models.md.
"""

from radarcl.errors import ConfigError
from radarcl.models.base import BeamGeometry, Choice, EvidenceModel, Number
from radarcl.models.detstats import DetStats
from radarcl.models.eq12 import Eq12, Occlusion

MODELS = {}


def register(model):
    """Add ``model`` (an ``EvidenceModel``) to ``MODELS``: ``interpret.model`` and its help take it
    from then on. A name already taken is refused."""
    if not isinstance(model, EvidenceModel) or not isinstance(model.name, str) or not model.name:
        raise ConfigError(f"an evidence model is an EvidenceModel with a name, got {model!r}")
    if model.name in MODELS:
        raise ConfigError(f"an evidence model named {model.name!r} is registered already")
    MODELS[model.name] = model
    return model


def get(name):
    """The registered model called ``name``; ConfigError naming the others."""
    try:
        return MODELS[name]
    except (KeyError, TypeError):
        raise ConfigError(f"unknown evidence model {name!r}; models: {', '.join(MODELS)}") from None


def names():
    """The registered models' names, in registration order."""
    return tuple(MODELS)


for _model in (Eq12(), Occlusion(), DetStats()):      # this order is the order of their keys
    register(_model)

__all__ = ["MODELS", "BeamGeometry", "Choice", "EvidenceModel", "Number", "get", "names", "register"]
