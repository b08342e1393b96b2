"""The ROS side of a parameter table (:class:`biped_sim.config.parameters.Param` entries), shared by both nodes.

Owns how a node turns its table into ROS parameters: the ROS type and ``ParameterDescriptor`` of an
entry, what an entry accepts in words, and :func:`declare_from_table`, which reads what was given
(``-p`` or a params file), refuses an unknown name or a bad value with one paragraph, and declares
every entry with its checked value. Only public rclpy API: the node is built with
``automatically_declare_parameters_from_overrides=True`` (the one public way to see every name that
was given, also those no table knows, which rclpy alone would ignore silently); each given table
entry is then undeclared and declared again with its type, range and checked value.
"""
from __future__ import annotations

import difflib

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rcl_interfaces.srv import ListParameters
from rclpy.parameter import Parameter

from biped_sim.config.parameters import Param, validate
from biped_sim.ros.startup import StartupError

#: parameters that rclpy itself declares or reads; given on the command line, they are ROS's, not ours
ROS_OWN_PARAMETERS = ("use_sim_time", "start_type_description_service")
ROS_OWN_PREFIXES = ("qos_overrides.",)


def allowed_values(p: Param) -> str:
    """What a parameter accepts, in words."""
    if p.type is list:
        kind = f"list of {p.item.__name__}" + (f" with {p.length} entries" if p.length else
                                               " with one entry per coordinate of the robot" if p.coordinates
                                               else "")
        if p.choices:
            kind += f", each one of {list(p.choices)}"
        return kind
    kind = {float: "double", int: "integer", bool: "bool (true/false)", str: "string"}[p.type]
    if p.choices:
        return f"{kind}, one of {list(p.choices)}"
    if p.file_name:
        return f"{kind}, a plain name (no '/' or '\\': it becomes part of a file name)"
    if p.low is not None or p.high is not None:
        return f"{kind} in [{p.low}, {p.high}]"
    return kind


def usage_text(program: str, node_name: str, summary: str, table: list, subscribes: dict, publishes: dict) -> str:
    """What ``program --help`` prints: how to give parameters, the topics ({name: type}) and every
    entry of ``table`` with what it accepts and its default."""
    def topics(d):
        return ", ".join(f"{name} ({kind})" for name, kind in d.items())
    lines = [f"usage: {program} [--ros-args [-p NAME:=VALUE ...] [--params-file FILE] [-r __node:=NAME]]", "",
             summary, "",
             f"The node is named '{node_name}': a params file gives its parameters under "
             f"'{node_name}: ros__parameters:'.",
             f"Subscribes: {topics(subscribes)}", f"Publishes: {topics(publishes)}", "",
             "Parameters (-p NAME:=VALUE, or a params file; lists of numbers written as floats, e.g. [0.0, 1.0]):"]
    for p in table:
        lines.append(f"  {p.name}: {allowed_values(p)}; default {p.default!r}")
        lines.append(f"      {p.description}")
    return "\n".join(lines)


def ros_type(p: Param) -> Parameter.Type:
    if p.type is list:
        return Parameter.Type.DOUBLE_ARRAY if p.item is float else Parameter.Type.STRING_ARRAY
    return {float: Parameter.Type.DOUBLE, int: Parameter.Type.INTEGER, bool: Parameter.Type.BOOL,
            str: Parameter.Type.STRING}[p.type]


def descriptor(p: Param) -> ParameterDescriptor:
    """rcl_interfaces/ParameterDescriptor of a table entry (type, description, range, choices)."""
    d = ParameterDescriptor(name=p.name, type=ros_type(p).value,
                            description=f"{p.description} ({allowed_values(p)}; default {p.default!r})")
    if p.choices:
        d.additional_constraints = f"one of {list(p.choices)}"
    if p.type is float and p.low is not None and p.high is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(p.low), to_value=float(p.high), step=0.0)]
    if p.type is int:
        lo = min(p.choices) if p.choices else p.low
        hi = max(p.choices) if p.choices else p.high
        if lo is not None and hi is not None:
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
    return d


def _plain(value):
    """A parameter's value as plain Python (lists, not array.array)."""
    if isinstance(value, (str, bytes, bool, int, float)) or value is None:
        return value
    try:
        return list(value)
    except TypeError:
        return value


def is_ros_own(name: str) -> bool:
    return name in ROS_OWN_PARAMETERS or name.startswith(ROS_OWN_PREFIXES)


def given_parameters(node) -> dict:
    """{name: value} of every parameter declared on ``node`` so far: built with
    ``automatically_declare_parameters_from_overrides=True``, that is every one given (``-p``, params
    file) plus those rclpy declared itself (see :func:`is_ros_own`)."""
    listed = node.list_parameters([], ListParameters.Request.DEPTH_RECURSIVE)
    return {name: _plain(node.get_parameter(name).value) for name in listed.names}


def unknown_parameters_message(unknown: list, table: list, node_name: str) -> str:
    hints = []
    for n in unknown:
        close = difflib.get_close_matches(n, [p.name for p in table], n=1)
        hints.append(f"'{n}'" + (f" (did you mean '{close[0]}'?)" if close else ""))
    return (f"unknown parameter {', '.join(hints)} for node '{node_name}'. Allowed parameters: "
            + "; ".join(f"{p.name} ({allowed_values(p)})" for p in table) + ".")


def check_given(given: dict, table: list, node_name: str, validator=validate) -> dict:
    """Every entry of ``table`` with its value (given, checked, or the default); StartupError names
    an unknown name (with the closest known one) or a bad value (with what it accepts). ``validator(values,
    table)`` checks the values and fills in the defaults (``config.parameters.validate``; the walk_controller
    node's fills in its law's own)."""
    by_name = {p.name: p for p in table}
    unknown = sorted(n for n in given if n not in by_name and not is_ros_own(n))
    if unknown:
        raise StartupError(unknown_parameters_message(unknown, table, node_name))
    try:
        return validator({n: v for n, v in given.items() if n in by_name}, table)
    except ValueError as exc:
        culprit = next((p for p in table if f"'{p.name}'" in str(exc)), None)
        extra = f" Allowed values of '{culprit.name}': {allowed_values(culprit)}." if culprit else ""
        raise StartupError(f"{exc}.{extra}") from None


def declare_from_table(node, table: list, validator=validate) -> dict:
    """Check what was given to ``node`` against ``table`` (``validator``, as :func:`check_given`), declare every
    entry (type, range, checked value), refuse later changes; returns {name: value}. Call it first in the
    node's ``__init__``."""
    values = check_given(given_parameters(node), table, node.get_name(), validator)
    for p in table:
        if node.has_parameter(p.name):        # declared from the override, with the type rcl parsed
            node.undeclare_parameter(p.name)
        node.declare_parameter(p.name, ros_type(p), descriptor(p), ignore_override=True)
    # declared typed but unset, then set: a value alone would not carry the type of an empty list
    node.set_parameters([Parameter(p.name, ros_type(p), values[p.name]) for p in table])
    ours_names = frozenset(p.name for p in table)
    reason = f"{node.get_name()} reads its parameters at start: restart the node to change them"

    def refuse_changes(params):
        ours = [p.name for p in params if p.name in ours_names]
        return SetParametersResult(successful=not ours, reason=reason if ours else "")
    node.add_on_set_parameters_callback(refuse_changes)
    return values


def value_less_override_message(exc: ValueError) -> str | None:
    """The refusal for rclpy's error on a parameter given without a value (``-p name:=[]``, or
    ``null`` in a params file), or None for any other ValueError. rclpy raises it while declaring the
    overrides, before the node can say which one (its message names none)."""
    if "PARAMETER_NOT_SET" not in str(exc):
        return None
    return ("a parameter is given without a value (an empty list [] or null): rclpy cannot declare a "
            "parameter that has no type. Give it a value, or leave it out for its default")
