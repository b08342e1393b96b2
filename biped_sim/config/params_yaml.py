"""Read a ROS 2 parameters file as the node does (rcl's ``rcl_yaml_param_parser``), without ROS.

Owns :func:`load`, the one reader of scene and parameters files outside rcl (the scene loader, and
the node's check of its ``--params-file`` sections). PyYAML reads YAML 1.1; rcl reads the structure
with libyaml and each unquoted scalar with its own rules, so one file gave the node and the
headless tools two different runs. Measured with rclpy (Jazzy) against ``yaml.safe_load``:

==================  =====================  ================
value               rcl (the node)         PyYAML
==================  =====================  ================
``1e3``, ``1.0e3``  1000.0                 the string '1e3'
``09``              9.0                    the string '09'
``y``, ``n``        true, false            'y', 'n'
``1_000``           the string '1_000'     1000
``0b101``, ``1:30`` strings                5, 90
``~``, ``null``     the strings '~', 'null'  None
``!!float 1``       1 (only !!str counts)  1.0
``[0, 1.5]``        refused (mixed types)  [0, 1.5]
==================  =====================  ================

Agreeing already: ``yes``/``no``/``on``/``off`` (booleans), ``010`` (octal: 8), ``0x10``, ``+5``,
``.inf``, ``.nan``, quoted scalars (strings). :func:`load` reads every unquoted scalar by rcl's rules
(``get_value`` in rcl_yaml_param_parser/src/parse.c: its boolean words, then ``strtol(s, 0)``, then
``strtod``, else a string), and refuses, with one line naming the key and what to write, what rcl
refuses (an empty value, a list mixing types) and what the two read differently with no error from
either: a key given twice in one mapping (rcl keeps the last value of a parameter, but merges two
sections of one node; PyYAML keeps the last of each).
"""
from __future__ import annotations

import math
import re
import sys

import yaml

_TRUE = frozenset(("Y", "y", "yes", "Yes", "YES", "true", "True", "TRUE", "on", "On", "ON"))
_FALSE = frozenset(("N", "n", "no", "No", "NO", "false", "False", "FALSE", "off", "Off", "OFF"))
_SPECIAL = {s: float(s.replace(".", "")) for s in (".nan", ".NaN", ".NAN", ".inf", ".Inf", ".INF", "+.inf",
                                                   "+.Inf", "+.INF", "-.inf", "-.Inf", "-.INF")}
#: what strtol(s, NULL, 0) reads whole: decimal, 0x hexadecimal, 0 octal
_INT = re.compile(r"\s*[+-]?(?:0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)")
#: what strtod reads whole: decimal (dot and exponent optional), hexadecimal, inf, infinity, nan
_DECIMAL = re.compile(r"\s*[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_HEX_FLOAT = re.compile(r"\s*[+-]?0[xX](?:[0-9a-fA-F]+\.?[0-9a-fA-F]*|\.[0-9a-fA-F]+)(?:[pP][+-]?[0-9]+)?")
_WORD_FLOAT = re.compile(r"\s*[+-]?(?:inf(?:inity)?|nan(?:\([0-9A-Za-z_]*\))?)", re.IGNORECASE)
_INT64 = (-2 ** 63, 2 ** 63 - 1)
STR_TAG = "tag:yaml.org,2002:str"


class _Loader(yaml.SafeLoader):
    """Notes on each scalar whether it was tagged ``!!str``, the one tag rcl honours (a composed
    node carries the resolved tag only: PyYAML resolves ``1e3`` and ``y`` to str as well)."""

    def compose_scalar_node(self, anchor):
        tagged_str = self.peek_event().tag == STR_TAG
        node = super().compose_scalar_node(anchor)
        node.tagged_str = tagged_str
        return node


class ParamsFileError(ValueError):
    """A parameters file the node (rcl) and a YAML reader would read differently, or rcl refuses."""


def rcl_scalar(text: str):
    """An unquoted scalar as rcl reads it: bool, int, float or str."""
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    if _INT.fullmatch(text):
        s = text.strip()
        digits = s.lstrip("+-")
        base = 16 if digits[:2] in ("0x", "0X") else 8 if digits.startswith("0") and len(digits) > 1 else 10
        value = int(s, base)
        if _INT64[0] <= value <= _INT64[1]:
            return value            # beyond int64 strtol says ERANGE and strtod reads it
    if text in _SPECIAL:
        return _SPECIAL[text]
    if _DECIMAL.fullmatch(text) or _WORD_FLOAT.fullmatch(text):
        s = text.strip()
        value = float("nan" if s.lstrip("+-").lower().startswith("nan") else s)
        if s.lower().startswith("-nan"):
            value = -value
    elif _HEX_FLOAT.fullmatch(text):
        value = float.fromhex(text.strip())
    else:
        return text
    word = _WORD_FLOAT.fullmatch(text) is not None
    if (math.isinf(value) and not word) or (0 < abs(value) < sys.float_info.min) or (
            value == 0 and re.search(r"[1-9]", text.split("e")[0].split("E")[0])):
        return text                 # strtod's ERANGE (overflow, underflow): rcl keeps the text
    return value


def _kind(value) -> str:
    return {bool: "true/false", int: "integer", float: "float", str: "string"}[type(value)]


def load(text: str, source) -> object:
    """The document of ``text`` (a parameters file, ``source`` names it in errors) as rcl reads it:
    mappings, lists and scalars; ParamsFileError (one line) for what rcl refuses or reads otherwise
    than a YAML reader; yaml.YAMLError for text that is not YAML."""
    loader = _Loader(text)
    try:
        root = loader.get_single_node()
    finally:
        loader.dispose()
    return None if root is None else _value(root, [], source)


def _where(path, node) -> str:
    return f"'{'.'.join(path)}' (line {node.start_mark.line + 1})"


def _value(node, path, source):
    if isinstance(node, yaml.MappingNode):
        out, lines = {}, {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode):
                raise ParamsFileError(f"{source}: a key under '{'.'.join(path) or 'the top level'}' (line "
                                      f"{key_node.start_mark.line + 1}) is not a name; write 'name: value'")
            key = key_node.value
            if key in out:
                first, again = lines[key], key_node.start_mark.line + 1
                dotted = ".".join(path + [key])
                if isinstance(value_node, yaml.MappingNode):
                    what = (f"rcl (the node) would merge the two and a YAML reader keep only the second, each "
                            f"silently: write '{key}:' once, with everything under it")
                else:
                    values = f"{out[key]!r} and {_value(value_node, path + [key], source)!r}"
                    what = (f"rcl (the node) would take the second silently: write '{key}' once, with the value "
                            f"it should have ({values} given)")
                raise ParamsFileError(f"{source}: '{dotted}' is given twice (lines {first} and {again}); {what}")
            lines[key] = key_node.start_mark.line + 1
            out[key] = _value(value_node, path + [key], source)
        return out
    if isinstance(node, yaml.SequenceNode):
        items = []
        for item in node.value:
            if not isinstance(item, yaml.ScalarNode):
                raise ParamsFileError(f"{source}: {_where(path, node)} holds a list or a mapping; a parameter's "
                                      "list holds numbers, strings or true/false")
            items.append(_scalar(item, path, source))
        kinds = [_kind(v) for v in items]
        if len(set(kinds)) > 1:
            fix = ("write every number with a decimal point (0.0, not 0)" if set(kinds) == {"integer", "float"}
                   else "write every entry of one type (quote the strings)")
            raise ParamsFileError(f"{source}: the list {_where(path, node)} mixes {' and '.join(sorted(set(kinds)))} "
                                  f"entries ({', '.join(repr(v) for v in items)}), which rcl refuses (the node would "
                                  f"not start): {fix}")
        return items
    return _scalar(node, path, source)


def _scalar(node, path, source):
    if node.style in ("'", '"') or getattr(node, "tagged_str", False):
        return node.value
    if node.value == "":
        raise ParamsFileError(f"{source}: {_where(path, node)} has no value, which rcl refuses: write a value "
                              "(quote an empty string: '') or leave the key out for its default")
    return rcl_scalar(node.value)
