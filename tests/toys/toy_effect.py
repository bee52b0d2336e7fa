"""A toy unmodelled effect, the whole of it: a grounded spring along the axis of the last link at the
tip (its stiffness k_N_per_m), with its fit range and its handle for the fast parametric model."""

from dataclasses import replace

from flexmodal.models import effects as fx
from flexmodal.models.rig import Point, Spring

NAME = "tip_axial_spring"


def tip_point(rig):
    return Point(rig.links[-1].name, 1.0)


def _fit(rig, location):
    last = rig.links[-1]
    ref = last.section.EA_N / last.length_m
    return (fx.Param(NAME, "k_N_per_m", "ka@tip", 0, *fx.log_range(ref, 1e-5, 1e1, 7)),)


fx.register_effect(fx.Effect(
    NAME, (fx.EffectParam("k_N_per_m", "N/m"),),
    locations=lambda rig: ["tip"],
    apply=lambda rig, loc, v, pose: replace(rig, springs=rig.springs + (
        Spring(tip_point(rig), v["k_N_per_m"], "axial", name=f"{NAME}@tip"),)),
    fit=_fit,
    handles=lambda rig: [fx.Handle("ka@tip", "K", 0.0, NAME)],
    rows=lambda system, srig, h: system.observe(f"{srig.links[-1].name}@1", "axial")[None],
    slots=lambda rig, srig: replace(srig, springs=srig.springs + (
        Spring(tip_point(rig), 0.0, "axial", name="slot@tip_axial"),)),
))
