"""The Foxglove layout against a real bag (issue 33): every topic and message path it names exists
in a bag that ``biped-sim simulate --record`` writes, and the torso angle has a plot of its own
(beside the ~3 rad leg angles its ~0.3 rad swing read as a flat line)."""
import json
import re
from pathlib import Path

from biped_sim.cli import main as biped_sim
from biped_sim.recording import bagio

LAYOUT = Path(__file__).resolve().parents[2] / "foxglove" / "biped_sim_layout.json"


def _panels():
    return json.loads(LAYOUT.read_text())["configById"]


def _resolve(msg, path: str):
    """The value at a Foxglove message path's field part (``wrench.force.y``, ``position[4]``), or
    raise AttributeError / IndexError where the message has no such field or element."""
    value = msg
    for name, index in re.findall(r"([A-Za-z_]\w*)(?:\[(\d+)\])?", path):
        value = getattr(value, name)
        if index:
            value = value[int(index)]
    return value


def test_every_topic_and_field_the_layout_names_is_in_a_recorded_bag(tmp_path):
    assert biped_sim(["simulate", "--scene", "walk", "--duration", "1", "--record", str(tmp_path)]) == 0
    bag = next(tmp_path.iterdir())
    types = bagio.channels(bag)
    first = {}
    for topic, type_name, _t, data in bagio.messages(bag):
        first.setdefault(topic, bagio.decode(type_name, data))
    panels = _panels()
    named = set(panels["3D!biped"]["topics"])
    named |= {c["topicPath"] for k, c in panels.items() if k.startswith("RawMessages!")}
    paths = [p["value"] for k, c in panels.items() if k.startswith("Plot!") for p in c["paths"]]
    named |= {p.split(".", 1)[0] for p in paths}
    assert named - set(types) == set(), f"the layout names topics the bag does not have: {named - set(types)}"
    assert named - set(first) == set(), "a named topic has no message in a 1 s walk"
    for path in paths:
        topic, field = path.split(".", 1)
        value = _resolve(first[topic], field)
        assert isinstance(value, float), (path, value)


def test_the_torso_angle_has_a_plot_of_its_own():
    plots = {k: [p["value"] for p in c["paths"]] for k, c in _panels().items() if k.startswith("Plot!")}
    (torso,) = [paths for paths in plots.values() if "/joint_states.position[4]" in paths]
    assert torso == ["/joint_states.position[4]"]
