"""Every pydantic model in tagloc has StrictModel's settings: unknown keys, NaN and infinities
are errors, and values are immutable."""

from __future__ import annotations

import importlib
import math
import pkgutil

import pydantic
import pytest

import tagloc
from tagloc.config import StrictModel
from tagloc.eval import EvalConfig
from tagloc.mapping.config import MapBuildConfig
from tagloc.sim.odometry import DriftParameters
from tagloc.tags.covariance import NoiseModel
from tagloc.tags.gates import GateConfig

#: Optional integrations whose framework is an extra (``tagloc[dimos]``): their models are
#: checked where the extra is installed (``make test-dimos``).
OPTIONAL = ("tagloc.adapters.dimos",)


def _models() -> list[type[pydantic.BaseModel]]:
    def skip(name: str) -> bool:
        return any(name == o or name.startswith(o + ".") for o in OPTIONAL)

    for info in pkgutil.walk_packages(tagloc.__path__, "tagloc.", onerror=lambda name: None):
        if skip(info.name):
            try:
                importlib.import_module(info.name)
            except ModuleNotFoundError:
                continue
        else:
            importlib.import_module(info.name)
    seen: list[type[pydantic.BaseModel]] = []
    todo = [pydantic.BaseModel]
    while todo:
        for sub in todo.pop().__subclasses__():
            todo.append(sub)
            if sub.__module__.startswith("tagloc.") and sub not in seen:
                seen.append(sub)
    return sorted(seen, key=lambda m: f"{m.__module__}.{m.__qualname__}")


def test_every_model_has_the_strict_settings() -> None:
    models = _models()
    assert StrictModel in models and len(models) > 40
    loose = {
        f"{m.__module__}.{m.__qualname__}": {k: m.model_config.get(k) for k in
                                             ("extra", "frozen", "allow_inf_nan")}
        for m in models
        if (m.model_config.get("extra"), m.model_config.get("frozen"),
            m.model_config.get("allow_inf_nan")) != ("forbid", True, False)
    }  # fmt: skip
    assert loose == {}


@pytest.mark.parametrize(
    ("model", "field"),
    [
        (GateConfig, "max_range_m"),
        (NoiseModel, "sigma_px"),
        (EvalConfig, "position_tol_m"),
        (MapBuildConfig, "outlier_sigma"),
        (DriftParameters, "scale_error"),
    ],
)
@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_non_finite_value_is_refused(
    model: type[pydantic.BaseModel], field: str, bad: float
) -> None:
    assert field in model.model_fields
    with pytest.raises(pydantic.ValidationError, match="finite"):
        model.model_validate({field: bad})
