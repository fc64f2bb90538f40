"""Helpers of the effect tests: a short noise-free lab run, and which plant fields an
effect changed."""

import dataclasses

import numpy as np

from cdpr_pipeline.sim.lab import simulate_lab
from cdpr_pipeline.sim.sensors import Sensors

IDEAL = Sensors(0.0, 0, 0.0)
COUNTS = {"oblique_circle": 1, "flat_eight": 1, "spiral": 1}


def run_lab(rig, effects, duration=4.0, seed=0):
    return simulate_lab(rig, COUNTS, effects=effects, duration_s=duration, seed=seed,
                        sensors=IDEAL)


def plant_fields(plant):
    return {f.name: getattr(plant, f.name) for f in dataclasses.fields(plant)}


def changed_fields(a, b):
    out = set()
    for key, va in plant_fields(a).items():
        vb = getattr(b, key)
        if key == "winch":
            if not np.array_equal(va.as_matrix(), vb.as_matrix()):
                out.add(key)
        elif key == "effects":
            if tuple(va) != tuple(vb):
                out.add(key)
        elif va is None or vb is None:
            if (va is None) != (vb is None):
                out.add(key)
        elif not np.array_equal(np.asarray(va), np.asarray(vb)):
            out.add(key)
    return out
