"""The scene bundles a hand, an object and a motion, and refuses anything else."""

import pytest

from regrasp_pin.exceptions import InputError
from regrasp_pin.model.scene import Scene
from regrasp_pin.scenarios import make_scenario


def test_scene_is_frozen():
    scen = make_scenario("five_finger", "hexagon")
    scene = Scene(scen.hand, scen.obj, scen.motion)
    with pytest.raises(AttributeError):
        scene.hand = scen.hand  # type: ignore[misc]


@pytest.mark.parametrize("wrong", ["hand", "obj", "motion"])
def test_scene_names_the_argument_of_the_wrong_type(wrong):
    scen = make_scenario("five_finger", "hexagon")
    parts = {"hand": scen.hand, "obj": scen.obj, "motion": scen.motion}
    parts[wrong] = "not it"
    with pytest.raises(InputError) as err:
        Scene(**parts)
    assert err.value.argument == wrong


def test_millimetres_by_mistake_are_refused_with_a_hint():
    from regrasp_pin.model.motion import ObjectMotion
    from regrasp_pin.model.objects import Box, Prism

    with pytest.raises(InputError) as err:
        Prism(6, 32, 40)
    assert err.value.argument == "circumradius_m" and "0.032" in str(err.value)
    with pytest.raises(InputError, match="size"):
        Box((40, 50, 50))
    scen = make_scenario("five_finger", "hexagon")
    T = scen.motion.T_palm_object.copy()
    T[:, :3, 3] *= 1000.0  # the object 55 m from the palm
    far = ObjectMotion.from_poses(scen.motion.times_s, T)
    with pytest.raises(InputError) as err:
        Scene(scen.hand, scen.obj, far)
    assert err.value.argument == "motion" and "metres" in str(err.value)
