"""The reduced plant's mission loop in compiled code (eq. 22): many steps in one call.

Step k: the rigid-body terms at (q_k, v_k) (:mod:`pipeline.sim.rigid_body_terms`), the
references at τ_k (:func:`~pipeline.sim.base_guidance.reference_vector`), the controller
(:func:`~pipeline.sim.control_step.controller_step`: row k and the state of step k + 1, but q),
then q_{k+1} = q_k ⊕ v_{k+1} dt (:func:`~pipeline.sim.configuration.integrate_configuration`).
Between steps nothing returns to Python, which cost a Python step about a sixth of its time
(issue 48). The mission (:meth:`pipeline.sim.mission.Mission.run`) calls it a slice of steps at
a time, and does what needs Python after each slice: the guard's messages, the log's chunks and
the progress bar. The sampled-data plant keeps its Python step (its sensors' and arrivals'
random streams, its queue of held commands).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from pipeline.sim.base_guidance import reference_vector
from pipeline.sim.configuration import integrate_configuration
from pipeline.sim.control_step import STEP_PLACES, controller_step
from pipeline.sim.jit import jit
from pipeline.sim.rigid_body_terms import dynamics_terms

# How a slice of steps ended (:func:`fly_reduced`'s first value).
FLOWN, NOT_FINITE, DIVERGED = 0, 1, 2


class ReducedLoop(NamedTuple):
    """What the loop reads besides the state and the log, by name: the robot's terms bundle
    (``RobotTerms``), the guidance's constants (``GUIDANCE_FIELDS``; empty: the reference
    vector handed in is held, the linearisation's fixed reference), the controller vector
    (``controller_fields``), the coverage counter, the arm's index in ``STEP_PLACES``, the
    row's place of the v_max clip's flag and the divergence criterion (steps on the clip)."""

    bundle: tuple
    guidance: np.ndarray
    controller: np.ndarray
    coverage: tuple
    shape_index: int
    clip_flag: int
    divergence_steps: int


@jit
def fly_reduced(loop, ref, state, rows, start, stop, clip):
    """Rows ``start`` to ``stop`` − 1 of ``rows``, one step each, from ``state`` (advanced in
    place, q included). ``clip`` = [consecutive steps on the v_max clip, the row being
    flown]: carried between calls, and the row of a step that raised. Returns (``FLOWN``,
    ``stop``), or (``NOT_FINITE``, i) when step i's new state is not finite, or
    (``DIVERGED``, i) when step i is the ``divergence_steps``-th on the clip in a row."""
    st = STEP_PLACES[loop.shape_index].state
    for i in range(start, stop):
        clip[1] = i
        q = state[st.q].copy()
        inputs = dynamics_terms(loop.bundle, q, state[st.v].copy())
        moving = loop.guidance.size > 0  # a boolean, not the literal True: one specialisation
        if moving:  # else a fixed reference, ``ref`` as it was handed in
            reference_vector(ref, state[st.tau], inputs.p_b, moving, loop.guidance)
        finite = controller_step(inputs, ref, loop.controller, state, rows, i, loop.coverage,
                                 loop.shape_index)
        q_new = integrate_configuration(q, state[st.dq].copy())
        state[st.q] = q_new
        if not finite:
            return NOT_FINITE, i
        for x in q_new:
            if not math.isfinite(x):
                return NOT_FINITE, i
        clip[0] = clip[0] + 1 if rows[i, loop.clip_flag] > 0.5 else 0
        if clip[0] >= loop.divergence_steps:
            return DIVERGED, i
    return FLOWN, stop


def new_clip() -> np.ndarray:
    """A fresh ``clip`` for :func:`fly_reduced`: no step on the clip yet, row 0."""
    return np.zeros(2, dtype=np.int64)
