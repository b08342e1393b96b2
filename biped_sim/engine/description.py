"""A planar robot described as data: links, joints, actuators, contact points, the floating base, the mirror.

Owns :class:`RobotDescription` and its two readers: :func:`description_from_dict` (the compact form, as
parsed from YAML by :mod:`biped_sim.config.models`) and :func:`description_from_urdf` (a planar URDF, read
with ``xml.etree``). docs/models.md is the reference of both forms.

Conventions (those of docs/model.md, for any chain): the robot moves in the x-z plane of a URDF, which
is the (x, y) plane of the model (y up). Every link has a frame whose z axis points along the link; a
frame at absolute angle ``a`` has its z axis at (sin a, cos a) and its x axis at (cos a, -sin a)
(angle 0 points up, a rotation about the plane's normal, a URDF's y axis). A point (px, pz) of a link
is ``o + px (cos a, -sin a) + pz (sin a, cos a)`` with ``o`` the link's joint. Coordinates:
``q = [base_x, base_y, <one angle per link, in the order the links are given>]``, the base link's
angle absolute (the floating base: its joint's position and angle), every other one relative to its
parent (``a = a_parent + sign * q_joint + offset``). An actuated joint's motor acts on its relative
angle, so B has a unit column per actuator. The mirror swaps pairs of links (left and right); the
relabeling R swaps their angles and the contact points on them, so R R = I.
"""
from __future__ import annotations

import hashlib
import json
import math
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass
from pathlib import Path


class DescriptionError(ValueError):
    """A robot description that cannot describe a planar robot; the message names the field."""


@dataclass(frozen=True)
class Link:
    """One rigid link, hanging from its parent by a revolute joint about the plane's normal."""
    name: str
    parent: str | None            # None: the base link (its joint is the floating base's angle)
    joint: str                    # the name of the link's coordinate
    origin: tuple[float, float]   # the joint's position in the parent's frame (x, z); (0, 0) for the base
    offset: float                 # the angle of the link's frame in the parent's at joint angle 0 (rad)
    sign: float                   # +1, or -1 for a joint turning about -y (a URDF axis 0 -1 0)
    length: float                 # from the joint to the link's tip along its z axis (m; drawing, tips)
    mass: float                   # kg, >= 0
    com: tuple[float, float]      # centre of mass in the link's frame (x, z) (m)
    inertia: float                # about the centre of mass and the plane's normal (kg m^2), >= 0


@dataclass(frozen=True)
class Contact:
    """A named contact point (a foot) fixed on a link: (x, z) in the link's frame."""
    name: str
    link: str
    point: tuple[float, float]


@dataclass(frozen=True)
class RobotDescription:
    """A planar floating-base robot. ``coordinates`` is ``q``'s order; ``relabeling`` is R as a permutation
    of ``q``'s indices; ``contact_mirror`` gives each contact point's mirror image's index."""
    name: str
    links: tuple[Link, ...]
    actuated: tuple[str, ...]
    contacts: tuple[Contact, ...]
    mirror: tuple[tuple[str, str], ...]
    gravity: float = 9.81
    source: str = ""

    @property
    def base(self) -> Link:
        return next(link for link in self.links if link.parent is None)

    @property
    def coordinates(self) -> tuple[str, ...]:
        return ("base_x", "base_y") + tuple(link.joint for link in self.links)

    @property
    def n(self) -> int:
        return 2 + len(self.links)

    @property
    def relabeling(self) -> tuple[int, ...]:
        index = {link.name: 2 + i for i, link in enumerate(self.links)}
        perm = list(range(self.n))
        for a, b in self.mirror:
            perm[index[a]], perm[index[b]] = index[b], index[a]
        return tuple(perm)

    @property
    def contact_mirror(self) -> tuple[int, ...]:
        swap = {a: b for a, b in self.mirror} | {b: a for a, b in self.mirror}
        out = []
        for c in self.contacts:
            other = swap.get(c.link, c.link)
            match = [j for j, d in enumerate(self.contacts) if d.link == other and d.point == c.point]
            out.append(match[0])
        return tuple(out)

    def structure(self) -> dict:
        """Everything that defines the dynamics, as plain data (the cache key hashes it)."""
        d = asdict(self)
        d.pop("source")
        return d

    def digest(self) -> str:
        return hashlib.sha256(json.dumps(self.structure(), sort_keys=True).encode()).hexdigest()[:16]


# ---- checks ----------------------------------------------------------------------------------------

def _fail(source, field, why):
    raise DescriptionError(f"robot description {source}: {field} {why}")


def _number(source, field, v, minimum=None):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        _fail(source, field, f"must be a finite number, got {v!r}")
    if minimum is not None and v < minimum:
        _fail(source, field, f"must be >= {minimum}, got {v!r}")
    return float(v)


def _pair(source, field, v, along_z_if_scalar=True):
    """A point (x, z) of a link's frame: a number is a distance along the link's z axis."""
    if isinstance(v, (list, tuple)):
        if len(v) != 2:
            _fail(source, field, f"must be a number (along the link) or [x, z], got {v!r}")
        return (_number(source, field, v[0]), _number(source, field, v[1]))
    return (0.0, _number(source, field, v)) if along_z_if_scalar else (_number(source, field, v), 0.0)


def check(desc: RobotDescription) -> RobotDescription:
    """``desc`` after checking that it is one planar tree with a floating base, named contact points, and a
    mirror that maps the robot onto itself; a DescriptionError names the field otherwise."""
    src = desc.source or desc.name
    if not desc.links:
        _fail(src, "links", "is empty: a robot needs at least one link")
    names = [link.name for link in desc.links]
    joints = [link.joint for link in desc.links]
    for what, seq in (("link", names), ("joint", joints), ("contact", [c.name for c in desc.contacts])):
        dup = sorted({s for s in seq if seq.count(s) > 1})
        if dup:
            _fail(src, f"{what} names", f"must be unique, {dup} repeated")
    clash = sorted(set(joints) & {"base_x", "base_y"})
    if clash:
        _fail(src, "joint names", f"{clash} are the floating base's coordinates: rename the joint")
    bases = [link.name for link in desc.links if link.parent is None]
    if len(bases) != 1:
        _fail(src, "links", f"must have exactly one base link (a link without parent), got {bases or 'none'}")
    by_name = {link.name: link for link in desc.links}
    for link in desc.links:
        if link.parent is not None and link.parent not in by_name:
            _fail(src, f"links.{link.name}.parent", f"names no link: {link.parent!r} (links: {', '.join(names)})")
        seen, p = set(), link
        while p.parent is not None:     # every chain ends at the base
            if p.name in seen:
                _fail(src, f"links.{link.name}.parent", "makes a loop: a robot description is a tree")
            seen.add(p.name)
            p = by_name[p.parent]
    for j in desc.actuated:
        if j not in joints:
            _fail(src, "actuated", f"names no joint: {j!r} (joints: {', '.join(joints)})")
        if by_name[names[joints.index(j)]].parent is None:
            _fail(src, "actuated", f"names the floating base's angle {j!r}: a motor acts between two links")
    if not desc.contacts:
        _fail(src, "contacts", "is empty: a walker needs named contact points (its feet)")
    for c in desc.contacts:
        if c.link not in by_name:
            _fail(src, f"contacts.{c.name}.link", f"names no link: {c.link!r}")
    if not desc.mirror:
        _fail(src, "mirror", "is empty: give the pairs of links that swap between left and right (the relabeling R)")
    paired = [n for pair in desc.mirror for n in pair]
    swap = {a: b for a, b in desc.mirror} | {b: a for a, b in desc.mirror}
    for a, b in desc.mirror:
        for n in (a, b):
            if n not in by_name:
                _fail(src, "mirror", f"names no link: {n!r}")
        if a == b or paired.count(a) > 1 or paired.count(b) > 1:
            _fail(src, "mirror", f"pairs each link once with another: [{a}, {b}]")
        la, lb = by_name[a], by_name[b]
        for f in ("origin", "offset", "sign", "length", "mass", "com", "inertia"):
            if getattr(la, f) != getattr(lb, f):
                _fail(src, f"mirror [{a}, {b}]", f"pairs links that differ in {f}: {getattr(la, f)!r} and "
                      f"{getattr(lb, f)!r} (the relabeling must map the robot onto itself)")
        if swap.get(la.parent, la.parent) != lb.parent:
            _fail(src, f"mirror [{a}, {b}]", f"pairs links whose parents {la.parent!r} and {lb.parent!r} are "
                  "not each other's mirror images")
    for c in desc.contacts:
        other = swap.get(c.link, c.link)
        if not any(d.link == other and d.point == c.point for d in desc.contacts):
            _fail(src, f"contacts.{c.name}", f"has no mirror image: no contact point at {list(c.point)} on {other!r}")
    if not any(swap.get(c.link, c.link) != c.link for c in desc.contacts):
        _fail(src, "mirror", "swaps no contact point: the feet must be on mirrored links")
    if sum(link.mass for link in desc.links) <= 0:
        _fail(src, "links", "have no mass")
    _number(src, "gravity", desc.gravity, 0.0)
    return desc


# ---- the compact form ------------------------------------------------------------------------------

LINK_FIELDS = {"parent", "joint", "origin", "offset", "axis", "length", "mass", "com", "inertia"}
TOP_FIELDS = {"name", "gravity", "links", "actuated", "contacts", "mirror"}


def description_from_dict(data, source: str = "<dict>") -> RobotDescription:
    """A description from its compact form (docs/models.md, "The compact form")."""
    if not isinstance(data, dict):
        _fail(source, "the file", f"must be a mapping with the fields {', '.join(sorted(TOP_FIELDS))}")
    unknown = sorted(set(data) - TOP_FIELDS)
    if unknown:
        _fail(source, "field(s)", f"{unknown} unknown; allowed: {', '.join(sorted(TOP_FIELDS))}")
    for key in ("name", "links", "contacts", "mirror"):
        if key not in data:
            _fail(source, key, "is missing")
    name = data["name"]
    if not isinstance(name, str) or not name.replace("_", "").isalnum():
        _fail(source, "name", f"must be a name of letters, digits and _, got {name!r}")
    raw_links = data["links"]
    if not isinstance(raw_links, dict):
        _fail(source, "links", "must be a mapping link name -> {parent, joint, length, mass, com, inertia, ...}")
    links = []
    for lname, spec in raw_links.items():
        where = f"links.{lname}"
        if not isinstance(spec, dict):
            _fail(source, where, "must be a mapping of the link's fields")
        unknown = sorted(set(spec) - LINK_FIELDS)
        if unknown:
            _fail(source, where, f"has unknown field(s) {unknown}; allowed: {', '.join(sorted(LINK_FIELDS))}")
        for key in ("joint", "mass"):
            if key not in spec:
                _fail(source, f"{where}.{key}", "is missing")
        axis = spec.get("axis", 1)
        if axis not in (1, -1):
            _fail(source, f"{where}.axis", f"must be 1 or -1 (the joint turns about +-the plane's normal), "
                  f"got {axis!r}")
        mass = _number(source, f"{where}.mass", spec["mass"], 0.0)
        inertia = _number(source, f"{where}.inertia", spec.get("inertia", 0.0), 0.0)
        links.append(Link(name=str(lname), parent=spec.get("parent"), joint=str(spec["joint"]),
                          origin=_pair(source, f"{where}.origin", spec.get("origin", 0.0)),
                          offset=_number(source, f"{where}.offset", spec.get("offset", 0.0)), sign=float(axis),
                          length=_number(source, f"{where}.length", spec.get("length", 0.0), 0.0),
                          mass=mass, com=_pair(source, f"{where}.com", spec.get("com", 0.0)), inertia=inertia))
    contacts = []
    raw_contacts = data["contacts"]
    if not isinstance(raw_contacts, dict):
        _fail(source, "contacts", "must be a mapping contact name -> {link, at}")
    by_name = {link.name: link for link in links}
    for cname, spec in raw_contacts.items():
        if not isinstance(spec, dict) or "link" not in spec:
            _fail(source, f"contacts.{cname}", "must be a mapping with link (and at: a point, default the link's tip)")
        link = by_name.get(spec["link"])
        at = spec.get("at", "tip")
        point = (0.0, link.length if link else 0.0) if at == "tip" else _pair(source, f"contacts.{cname}.at", at)
        contacts.append(Contact(str(cname), str(spec["link"]), point))
    mirror = data["mirror"]
    if not isinstance(mirror, list) or not all(isinstance(p, list) and len(p) == 2 for p in mirror):
        _fail(source, "mirror", f"must be a list of [left, right] link pairs, got {mirror!r}")
    actuated = data.get("actuated", [])
    if not isinstance(actuated, list):
        _fail(source, "actuated", f"must be a list of joint names, got {actuated!r}")
    return check(RobotDescription(name=name, links=tuple(links), actuated=tuple(map(str, actuated)),
                                  contacts=tuple(contacts), mirror=tuple((str(a), str(b)) for a, b in mirror),
                                  gravity=_number(source, "gravity", data.get("gravity", 9.81), 0.0), source=source))


# ---- planar URDF -----------------------------------------------------------------------------------

PLANE_NORMAL_TOL = 1e-12


def _floats(source, field, text, count=3):
    try:
        v = [float(s) for s in (text or "").split()]
    except ValueError:
        v = []
    if len(v) != count or not all(math.isfinite(x) for x in v):
        _fail(source, field, f"must be {count} numbers, got {text!r}")
    return v


def _attr_number(source, field, element, attr, default=None, minimum=None):
    """A number attribute of an element (``default`` when the element or the attribute is absent)."""
    text = element.get(attr) if element is not None else None
    if text is None:
        if default is None:
            _fail(source, field, f"is missing (attribute {attr})")
        return default
    try:
        v = float(text)
    except ValueError:
        _fail(source, field, f"must be a number, got {text!r}")
    return _number(source, field, v, minimum)


def _link_of(source, joint, element, tag):
    el = element.find(tag)
    if el is None or not el.get("link"):
        _fail(source, f"joint {joint!r}", f"has no <{tag} link=...>")
    return el.get("link")


def _origin(source, field, element):
    """(x, z, pitch) of an <origin>; a roll or a yaw is a pose out of the plane: refused."""
    o = element.find("origin") if element is not None else None
    if o is None:
        return 0.0, 0.0, 0.0
    x, _, z = _floats(source, f"{field} origin xyz", o.get("xyz", "0 0 0"))
    roll, pitch, yaw = _floats(source, f"{field} origin rpy", o.get("rpy", "0 0 0"))
    if abs(roll) > PLANE_NORMAL_TOL or abs(yaw) > PLANE_NORMAL_TOL:
        _fail(source, field, f"is not planar: its origin turns about x or z (rpy {o.get('rpy')}); only a pitch "
              "(about y, the plane's normal) keeps the robot in the x-z plane")
    return x, z, pitch


def description_from_urdf(path_or_text, name: str | None = None) -> RobotDescription:
    """A description from a planar URDF: every joint revolute (or continuous) about the y axis, or fixed to a
    massless leaf link (a contact frame). The floating base is the root link. A ``<biped_sim>`` element
    (ignored by other URDF readers) names the contacts, the mirror pairs and the actuated joints::

        <biped_sim>
          <contact name="foot_1" link="foot_1"/>   <!-- a frame link, or link= with xyz= on a link -->
          <mirror left="leg_1" right="leg_2"/>
          <actuated joint="hip_1"/>                 <!-- default: every joint with limit effort > 0 -->
        </biped_sim>
    """
    text = str(path_or_text)
    if text.lstrip().startswith("<"):
        source, xml = "<urdf text>", text
    else:
        source = text
        try:
            xml = Path(text).read_text()
        except OSError as e:
            raise DescriptionError(f"robot description {source}: cannot read it ({e.strerror})") from None
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as e:
        raise DescriptionError(f"robot description {source}: not well-formed XML ({e})") from None
    if root.tag != "robot":
        _fail(source, "the root element", f"must be <robot>, got <{root.tag}>")
    raw_links = {}
    for el in root.findall("link"):
        lname = el.get("name")
        inertial = el.find("inertial")
        mass, com, iyy = 0.0, (0.0, 0.0), 0.0
        if not lname:
            _fail(source, "a <link>", "has no name")
        if inertial is not None:
            mass = _attr_number(source, f"link {lname!r} mass value", inertial.find("mass"), "value", 0.0, 0.0)
            cx, cz, _ = _origin(source, f"link {lname!r} inertial", inertial)
            com = (cx, cz)
            iyy = _attr_number(source, f"link {lname!r} inertia iyy", inertial.find("inertia"), "iyy", 0.0, 0.0)
        raw_links[lname] = (mass, com, iyy)
    joints, children = [], {}
    for el in root.findall("joint"):
        jname, jtype = el.get("name"), el.get("type")
        parent, child = _link_of(source, jname, el, "parent"), _link_of(source, jname, el, "child")
        for lk in (parent, child):
            if lk not in raw_links:
                _fail(source, f"joint {jname!r}", f"names no link: {lk!r}")
        x, z, pitch = _origin(source, f"joint {jname!r}", el)
        if jtype in ("revolute", "continuous"):
            ax = _floats(source, f"joint {jname!r} axis", (el.find("axis").get("xyz") if el.find("axis") is not None
                                                           else "1 0 0"))
            norm = math.sqrt(sum(a * a for a in ax))
            if norm == 0 or abs(ax[0]) > PLANE_NORMAL_TOL * norm or abs(ax[2]) > PLANE_NORMAL_TOL * norm:
                _fail(source, f"joint {jname!r}", f"is not planar: it turns about axis ({' '.join(map(str, ax))}), "
                      "not the plane's normal (0 1 0); every joint of a planar robot turns about parallel axes")
            effort = _attr_number(source, f"joint {jname!r} limit effort", el.find("limit"), "effort", 0.0)
            joints.append(dict(name=jname, parent=parent, child=child, origin=(x, z), offset=pitch,
                               sign=1.0 if ax[1] > 0 else -1.0, effort=effort))
        elif jtype == "fixed":
            joints.append(dict(name=jname, parent=parent, child=child, origin=(x, z), offset=pitch, fixed=True))
        else:
            _fail(source, f"joint {jname!r}", f"has type {jtype!r}: a planar robot's joints are revolute (or "
                  "continuous) about y, or fixed to a contact frame; the floating base is implied")
        children.setdefault(parent, []).append(jname)
    child_of = {j["child"]: j for j in joints}
    roots = [lk for lk in raw_links if lk not in child_of]
    if len(roots) != 1:
        _fail(source, "links", f"must form one tree with one root (the floating base), got roots {roots}")
    frames = {}           # massless leaf links on fixed joints: contact frames
    for j in joints:
        if j.get("fixed"):
            mass = raw_links[j["child"]][0]
            if mass > 0 or j["child"] in children:
                _fail(source, f"joint {j['name']!r}", "is fixed to a link with mass or children: merge that link "
                      "into its parent (a fixed joint may only carry a contact frame)")
            frames[j["child"]] = (j["parent"], j["origin"])
    ext = root.find("biped_sim")
    links = []
    order = [roots[0]] + [j["child"] for j in joints if not j.get("fixed")]
    # keep the document's order of the links, the base where it stands
    order = [lk for lk in raw_links if lk in order]
    for lk in order:
        mass, com, iyy = raw_links[lk]
        j = child_of.get(lk)
        tips = [jj["origin"][1] for jj in joints if jj["parent"] == lk]
        length = max([abs(t) for t in tips], default=0.0)
        if j is None:
            links.append(Link(lk, None, f"{lk}_pitch", (0.0, 0.0), 0.0, 1.0, length, mass, com, iyy))
        else:
            links.append(Link(lk, j["parent"], j["name"], j["origin"], j["offset"], j["sign"], length, mass, com, iyy))
    contacts, mirror, actuated = [], [], None
    if ext is not None:
        for c in ext.findall("contact"):
            cname, clink = c.get("name"), c.get("link")
            if clink in frames:
                parent, point = frames[clink]
                contacts.append(Contact(cname or clink, parent, point))
            else:
                x, _, z = _floats(source, f"<biped_sim><contact name={cname!r}> xyz", c.get("xyz", "0 0 0"))
                contacts.append(Contact(cname or clink, clink, (x, z)))
        mirror = [(m.get("left"), m.get("right")) for m in ext.findall("mirror")]
        acts = ext.findall("actuated")
        if acts:
            actuated = [a.get("joint") for a in acts]
    if not contacts:
        contacts = [Contact(frame, parent, point) for frame, (parent, point) in frames.items()]
    if actuated is None:
        actuated = [j["name"] for j in joints if not j.get("fixed") and j["effort"] > 0]
    g = 9.81
    if ext is not None and ext.find("gravity") is not None:
        g = _attr_number(source, "<biped_sim><gravity value>", ext.find("gravity"), "value", None, 0.0)
    return check(RobotDescription(name=name or root.get("name") or "robot", links=tuple(links),
                                  actuated=tuple(actuated), contacts=tuple(contacts), mirror=tuple(mirror),
                                  gravity=g, source=source))


# ---- writing a planar URDF -------------------------------------------------------------------------

def to_urdf(desc: RobotDescription) -> str:
    """``desc`` as a planar URDF that :func:`description_from_urdf` reads back to ``desc`` (and that other
    URDF readers, Pinocchio's among them, read as the same robot with the floating base left out): joints
    revolute about y with wide limits (a motor's joint has an effort limit), every contact point and every
    link's tip a massless frame on a fixed joint, the mirror and the contacts in a ``<biped_sim>`` element."""
    def f(v):
        return repr(float(v))
    lines = ['<?xml version="1.0"?>', f'<robot name="{desc.name}">']
    for link in desc.links:
        cx, cz = link.com
        lines += [f'  <link name="{link.name}">', "    <inertial>",
                  f'      <origin xyz="{f(cx)} 0 {f(cz)}" rpy="0 0 0"/>', f'      <mass value="{f(link.mass)}"/>',
                  f'      <inertia ixx="{f(link.inertia)}" ixy="0" ixz="0" iyy="{f(link.inertia)}" iyz="0" '
                  f'izz="{f(link.inertia)}"/>', "    </inertial>", "  </link>"]
    frames = [(c.name, c.link, c.point) for c in desc.contacts]
    child_z = {}
    for link in desc.links:
        if link.parent is not None:
            child_z.setdefault(link.parent, []).append(abs(link.origin[1]))
    for _, lk, p in frames:
        child_z.setdefault(lk, []).append(abs(p[1]))
    for link in desc.links:     # a tip the reader would not see from the children: a frame of its own
        if link.length != max(child_z.get(link.name, []), default=0.0):
            frames.append((f"{link.name}_tip", link.name, (0.0, link.length)))
    for name, _, _ in frames:
        lines.append(f'  <link name="{name}"/>')
    for link in desc.links:
        if link.parent is None:
            continue
        effort = "100.0" if link.joint in desc.actuated else "0.0"
        lines += [f'  <joint name="{link.joint}" type="revolute">', f'    <parent link="{link.parent}"/>',
                  f'    <child link="{link.name}"/>',
                  f'    <origin xyz="{f(link.origin[0])} 0 {f(link.origin[1])}" rpy="0 {f(link.offset)} 0"/>',
                  f'    <axis xyz="0 {f(link.sign)} 0"/>',
                  f'    <limit lower="-1000.0" upper="1000.0" effort="{effort}" velocity="1000.0"/>', "  </joint>"]
    for name, lk, (px, pz) in frames:
        lines += [f'  <joint name="{name}_frame" type="fixed">', f'    <parent link="{lk}"/>',
                  f'    <child link="{name}"/>', f'    <origin xyz="{f(px)} 0 {f(pz)}" rpy="0 0 0"/>', "  </joint>"]
    lines.append("  <biped_sim>")
    lines.append(f'    <gravity value="{f(desc.gravity)}"/>')
    lines += [f'    <contact name="{c.name}" link="{c.name}"/>' for c in desc.contacts]
    lines += [f'    <mirror left="{a}" right="{b}"/>' for a, b in desc.mirror]
    lines += [f'    <actuated joint="{j}"/>' for j in desc.actuated]
    lines += ["  </biped_sim>", "</robot>", ""]
    return "\n".join(lines)
