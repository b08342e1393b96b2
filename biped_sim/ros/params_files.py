"""The ``--params-file`` arguments of a node: refuse a file that gives this node nothing.

Owns the check that a parameters file applies to the node being started. rcl reads every file and
hands a node only the sections whose name matches the node's fully qualified name; a file with no
such section (a typo in the section name, a node renamed with ``-r __node:=`` or moved with ``-r
__ns:=``, an empty or a scalar file) was ignored without a word, and the node ran its defaults
(realtime, no end, recording) instead of the run the file describes. :func:`check_applies` names the
file, the sections found and the names that would apply.

rcl's rules (design article "ROS command line arguments", rcl_yaml_param_parser): a section is a
mapping holding ``ros__parameters``; its name is the keys above it joined by ``/`` (``ns: node:`` is
``ns/node``), a leading ``/`` is implied, ``*`` matches one token of the name and ``**`` any number
of them (``/**`` every node); partial wildcards (``bip*``) match nothing.
"""
from __future__ import annotations

import re

from biped_sim.config import params_yaml
from biped_sim.ros.startup import StartupError

PARAMETERS_KEY = "ros__parameters"


def params_files(argv: list) -> list:
    """The files given with ``--params-file FILE`` inside ``--ros-args ... [--]`` of ``argv``."""
    files, in_ros = [], False
    args = list(argv[1:])
    for i, a in enumerate(args):
        if a == "--ros-args":
            in_ros = True
        elif in_ros and a == "--":
            in_ros = False
        elif in_ros and a == "--params-file" and i + 1 < len(args):
            files.append(args[i + 1])
    return files


def sections(document) -> list:
    """The node names of a loaded params file, in file order (those holding ``ros__parameters``)."""
    found = []

    def walk(mapping, path):
        for key, value in mapping.items():
            if key == PARAMETERS_KEY and path:
                found.append("/".join(path))
            elif isinstance(value, dict):
                walk(value, path + [str(key).strip("/")])
    if isinstance(document, dict):
        walk(document, [])
    return found


def matches(section: str, fqn: str) -> bool:
    """Whether the section name ``section`` applies to the node ``fqn`` (e.g. ``/ns/biped_sim``)."""
    pattern = ""
    for token in section.strip("/").split("/"):
        if token == "**":
            pattern += "(/[^/]+)*"
        elif token == "*":
            pattern += "/[^/]+"
        else:
            pattern += "/" + re.escape(token)
    return re.fullmatch(pattern, fqn) is not None


def check_applies(node, argv: list):
    """StartupError naming a ``--params-file`` of ``argv`` none of whose sections applies to ``node``,
    or one that rcl and the headless tools would read differently (a key given twice: rcl merges two
    sections of a node and keeps the last of two values, silently; see params_yaml)."""
    import yaml
    fqn = node.get_fully_qualified_name()
    for path in params_files(argv):
        try:
            with open(path) as f:
                document = params_yaml.load(f.read(), f"the parameters file {path}")
        except params_yaml.ParamsFileError as exc:
            raise StartupError(str(exc)) from None
        except (OSError, yaml.YAMLError):
            continue            # rcl has read it already: it says what is wrong with it, not us
        names = sections(document)
        if any(matches(s, fqn) for s in names):
            continue
        if names:
            found = f"its sections {names} apply to other nodes"
        elif isinstance(document, dict) and document:
            found = f"it has no section with '{PARAMETERS_KEY}:' (top-level keys {list(document)})"
        else:
            found = "it is empty" if document is None else f"it holds no sections, only {document!r}"[:200]
        name = fqn.rsplit("/", 1)[-1]
        raise StartupError(
            f"the parameters file {path} gives node {fqn} nothing: {found}, so the node would run its "
            f"defaults instead. A section applies to this node if it is named '{name}:' (in the root "
            f"namespace), '{fqn}:' or '/**:', each with '{PARAMETERS_KEY}:' under it; or start the node under "
            "the name the file uses (-r __node:=NAME, -r __ns:=/NAMESPACE)")
