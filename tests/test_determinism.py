"""The same plan on every machine: numpy's SIMD kernels and OpenBLAS's must not change
a decision.

The planner runs twice in fresh processes: once as installed, once with numpy's
AVX2/AVX-512 kernels turned off (``NPY_DISABLE_CPU_FEATURES``), which changes the
last bits of many reductions; and once with OpenBLAS's kernels for the CPU and once
with an older family's (``OPENBLAS_CORETYPE``: AVX2 where the CPU has AVX-512, AVX
without FMA where it has AVX2), which changes the last bits of matrix products. Both
must give the same regrasps: the same fingers at the same times, landing on the same
contacts (within 0.1 mm). The same holds between the IK backends (numpy's loops and
the compiled ones).
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys

import numpy as np
import pytest

_SCRIPT = r"""
import json, sys
from regrasp_pin import make_scenario, plan_manipulation
from regrasp_pin.exceptions import PlanningError
from regrasp_pin.suite import build_scenario, neighbour_specs
from regrasp_pin.suite.specs import generate_specs
if sys.argv[1] == "demo":
    scen = make_scenario("five_finger", "hexagon", angle_deg=100, rate_deg_s=20)
elif sys.argv[1].startswith("spec "):  # "spec <seed> <index>" of the default suite
    _, seed, index = sys.argv[1].split()
    scen = build_scenario(generate_specs(int(index) + 1, seed=int(seed))[int(index)])
else:
    scen = build_scenario(next(s for s in neighbour_specs() if s.name == sys.argv[1]))
try:
    r = plan_manipulation(scen.hand, scen.obj, scen.motion, grasp=scen.grasp, params=scen.params)
    regrasps, failure = r.regrasps, None
except PlanningError as exc:
    regrasps = exc.partial.regrasps() if exc.partial is not None else []
    failure = [exc.kind.value, exc.finger, exc.time_s]
print(json.dumps({
    "vertices": scen.obj.vertices.tolist(),
    "grasp": {n: p.tolist() for n, p in scen.grasp.points_object.items()},
    "regrasps": [[g.finger, g.t_start, g.t_end, list(map(float, g.Q_object))] for g in regrasps],
    "failure": failure,
}))
"""


def _cpu_features() -> dict[str, bool]:
    """numpy's record of this CPU's SIMD features."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as feats
    except ImportError:  # numpy < 2
        from numpy.core._multiarray_umath import __cpu_features__ as feats
    return feats


def _wide_simd() -> list[str]:
    wide = ("X86_V3", "X86_V4", "AVX2", "AVX512F", "AVX512CD", "AVX512_SKX", "FMA3")
    return [f for f in wide if _cpu_features().get(f)]


def _avx512() -> bool:
    """Whether this CPU has AVX-512, for which OpenBLAS has kernels of its own."""
    return bool(_cpu_features().get("AVX512F"))


_KERNEL_VARIABLES = ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")


def _run(scenario: str, env_extra: dict[str, str]) -> dict:
    """The plan in a fresh process, with the kernels as installed but for ``env_extra``
    (a kernel variable set in this shell is dropped, so that each run changes one)."""
    env = {k: v for k, v in os.environ.items() if k not in _KERNEL_VARIABLES} | env_extra
    out = subprocess.run(
        [sys.executable, "-c", _SCRIPT, scenario],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@functools.cache
def _as_installed(scenario: str) -> dict:
    """The plan with numpy's and OpenBLAS's kernels as they pick them (run once per
    scenario and test process)."""
    return _run(scenario, {})


@pytest.mark.parametrize(
    "scenario",
    [
        "demo",
        # a 10 s turn with a neighbour making room, a hand-over and a finger held on
        "five_finger-hexagon--100deg-10dps",
    ],
)
def test_plan_does_not_change_without_the_wide_simd_kernels(scenario):
    wide = _wide_simd()
    if not wide:
        pytest.skip("this CPU has no AVX2/AVX-512 kernels to turn off")
    a = _as_installed(scenario)
    b = _run(scenario, {"NPY_DISABLE_CPU_FEATURES": " ".join(wide)})
    _assert_same_plan(a, b)


@pytest.mark.parametrize("coretype", ["Haswell", "Sandybridge"])
@pytest.mark.parametrize(
    "scenario",
    [
        "demo",
        # the Allegro turning a mesh while it moves: Hopfield ties on straight stretches
        # and contacts exactly a separation apart, which OpenBLAS's kernels once decided
        "spec 0 5",
    ],
)
def test_plan_does_not_change_with_openblas_kernels(scenario, coretype):
    """OpenBLAS's kernels for this CPU against an older family's: AVX2 (Haswell) where
    the CPU has AVX-512, AVX without FMA (Sandybridge) where it has AVX2."""
    if coretype == "Haswell" and not _avx512():
        pytest.skip("this CPU has no AVX-512: OpenBLAS runs its Haswell kernels already")
    if coretype == "Sandybridge" and not _cpu_features().get("AVX2"):
        pytest.skip("this CPU has no AVX2: OpenBLAS runs an older family already")
    a = _as_installed(scenario)
    b = _run(scenario, {"OPENBLAS_CORETYPE": coretype})
    _assert_same_plan(a, b)


@pytest.mark.parametrize("scenario", ["demo", "spec 0 5"])
def test_plan_does_not_change_with_the_other_ik_backend(scenario):
    """The compiled IK and placement loops (``REGRASP_PIN_IK_BACKEND=numba``, the
    ``fast`` extra) against numpy's: an accelerator may not change a plan."""
    pytest.importorskip("numba", reason="the numba backend needs the 'fast' extra")
    installed = os.environ.get("REGRASP_PIN_IK_BACKEND") or "numba"  # numba's when installed
    other = "numba" if installed == "numpy" else "numpy"
    _assert_same_plan(_as_installed(scenario), _run(scenario, {"REGRASP_PIN_IK_BACKEND": other}))


def _assert_same_plan(a: dict, b: dict) -> None:
    """The same object (its vertices to the bit), failure (or none), initial grasp and
    regrasps: fingers, times within 1e-6 s, new contacts within 0.1 mm."""
    assert a["vertices"] == b["vertices"]
    assert a["failure"] == b["failure"]
    for n in a["grasp"]:
        np.testing.assert_allclose(a["grasp"][n], b["grasp"][n], atol=1e-4)
    assert [r[0] for r in a["regrasps"]] == [r[0] for r in b["regrasps"]]
    assert len(a["regrasps"]) >= 1
    for ra, rb in zip(a["regrasps"], b["regrasps"], strict=True):
        assert abs(ra[1] - rb[1]) < 1e-6 and abs(ra[2] - rb[2]) < 1e-6, (ra, rb)
        np.testing.assert_allclose(ra[3], rb[3], atol=1e-4)
