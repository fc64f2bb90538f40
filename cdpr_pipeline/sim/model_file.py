"""Model files (``cdpr-model/1``): a rig plus effects with fixed parameters, as YAML.

``cdpr diagnose`` writes the extended model it found in this format; ``cdpr simulate
model_file=FILE`` runs it, so a diagnosis can be checked by simulating what it claims. The
rig is the nominal ``rig.yaml`` content (what the controller believes); the effects
make the simulated plant differ from it, exactly as hidden effects do in the virtual
lab. Effects are looked up by vocabulary name in the registry, never imported by path,
so a model file cannot load arbitrary code.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import yaml

from cdpr_pipeline.data.errors import DataValidationError
from cdpr_pipeline.data.rig import FORMAT, Rig
from cdpr_pipeline.data.validation import parse_rig
from cdpr_pipeline.sim.effects import ALIASES, EFFECTS, Effect, effect_class
from cdpr_pipeline.sim.plant import nominal_plant

MODEL_FORMAT = "cdpr-model/1"


def model_record(rig: Rig, effects: Sequence[Effect], **meta: Any) -> dict[str, Any]:
    """The YAML-able record of ``rig`` with ``effects``; ``meta`` is kept as is. The
    descriptions put per-winch sizes in relation to the rig's nominal parameters."""
    nominal = nominal_plant(rig, rig.coulomb_sharpness)
    return {"format": MODEL_FORMAT, **meta, "rig": rig.to_dict(),
            "effects": [{"effect": e.name, "params": e.params(),
                         "description": e.describe(nominal)} for e in effects]}


def write_model(path: str | Path, rig: Rig, effects: Sequence[Effect], **meta: Any) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(model_record(rig, effects, **meta), sort_keys=False))
    return path


def read_model_or_rig(path: str | Path) -> tuple[Rig, list[Effect]]:
    """The rig and effects of a model file (:func:`read_model`), or of a dataset's
    ``rig.yaml`` (or the dataset directory holding one): the nominal model, no effect.

    Raises
    ------
    ValueError
        As :func:`read_model`, naming the file.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "rig.yaml"
    try:
        record = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ValueError(f"{path}: cannot read model file ({err})") from err
    if isinstance(record, dict) and record.get("format") == FORMAT:
        rig, problems = parse_rig(record, file=str(path))
        if rig is None or any(p.severity == "error" for p in problems):
            raise DataValidationError(problems)
        return rig, []
    return read_model(path)


def read_model(path: str | Path) -> tuple[Rig, list[Effect]]:
    """The rig and effects of a model file.

    Raises
    ------
    ValueError
        Naming the file and the entry, for an unknown format, an unknown effect or a
        parameter the effect does not have.
    """
    path = Path(path)
    try:
        record = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise ValueError(f"{path}: cannot read model file ({err})") from err
    if not isinstance(record, dict) or record.get("format") != MODEL_FORMAT:
        raise ValueError(f"{path}: not a {MODEL_FORMAT} model file (format: "
                         f"{record.get('format') if isinstance(record, dict) else None!r})")
    rig, problems = parse_rig(record.get("rig") or {}, file=f"{path} (rig)")
    if rig is None or any(p.severity == "error" for p in problems):
        raise DataValidationError(problems)
    effects = []
    for k, entry in enumerate(record.get("effects") or []):
        name = entry.get("effect") if isinstance(entry, dict) else None
        if name not in EFFECTS and name not in ALIASES:
            raise ValueError(f"{path}: effects[{k}]: unknown effect {name!r}; "
                             f"known: {sorted(EFFECTS)}")
        try:
            effects.append(effect_class(name)(**(entry.get("params") or {})))
        except TypeError as err:
            raise ValueError(f"{path}: effects[{k}] ({name}): {err}") from err
    return rig, effects
