"""The keys a scene file may hold: one table that the loader reads and the
documentation renders.

Each :class:`Section` is one table of a scene file (``[scheme]``,
``[contacts.NAME.law]``, ...), sometimes for one ``type`` of what it
describes; each :class:`Key` of it gives the key's unit, its default (or
that it is required), the check its value must pass and a one-line meaning.
The loader (:class:`cosim.scene.checks.Table`) takes from here which keys a
table accepts, which are required and what the others default to, so the
reference that :func:`reference_markdown` writes cannot drift from what is
accepted.  Two sections are made from registries instead: the options of the
coupling schemes (``[scheme]``, from each scheme's ``options``) and the
parameters of the contact laws (``[contacts.NAME.law]``, from the fields of
each law's dataclass).

Key names in upper case (``NAME``, ``POINT``) stand for a name the scene
chooses.
"""
from __future__ import annotations

import dataclasses
import math

from cosim.scene.keytable import (_COMMON_STRUCTURE, _SUBSYSTEM_TYPE, DEFAULT_CONTACT_STEP,
                                  DEFAULT_MULTIBODY_STEP, REQUIRED, SECTIONS, Key, Section,
                                  Varies)

__all__ = ["Key", "Section", "SECTIONS", "REQUIRED", "Varies", "section", "law_section",
           "scheme_section", "structure_section", "reference_markdown", "DEFAULT_MULTIBODY_STEP",
           "DEFAULT_CONTACT_STEP", "LAW_PARAMETERS", "SCHEME_OPTIONS"]

K = Key

#: meaning and unit of each contact-law parameter (the laws' dataclass fields)
LAW_PARAMETERS = {
    "contact_stiffness": ("N/m^e", "penalty stiffness (N/m for the linear laws; N/m^e with "
                                   "an `exponent` e; Pa/m for a circle, `radius`)"),
    "contact_damping": ("N s/m", "viscous damping of the Kelvin-Voigt law"),
    "exponent": ("", "exponent e of the penetration (3/2 for Hertz's spheres)"),
    "reference_penetration": ("m", "penetration at which the stiffness is given "
                                   "(the stiffness is then in N/m)"),
    "hysteresis_damping": ("s/m", "Hunt-Crossley's damping factor chi"),
    "restitution": ("", "coefficient of restitution the law aims at"),
    "impact_speed": ("m/s", "the impact speed the law is tuned for"),
    "friction": ("", "Coulomb coefficient of a rigid law (impulse space)"),
}

#: meaning of each coupling-scheme option (the schemes' ``options``)
SCHEME_OPTIONS = {
    "macro_step": "the macro step: time between two exchanges of the sides",
    "extrapolation_order": "order of the force polynomial over a step (0 held, 1, 2)",
    "max_energy_gain": "energy an exchange may create, relative, before the step is refined",
    "accept_unsafe_step": "run a macro step the pre-flight check finds too long",
    "contact_step": "a shorter macro step while a coupler contact is closed",
    "approach_horizon": "how far ahead a coupler contact predicted to close shortens the "
                        "step to `contact_step` (default: `macro_step`)",
    "interface_tolerance": "refine the step while the interface error estimate exceeds this",
    "land_onsets": "end a contact step at an onset inside it (with `contact_step`)",
    "substeps": "sub-steps per macro step of each named subsystem (multirate)",
    "sequence": "the order in which Gauss-Seidel advances the moving subsystems",
    "max_iterations": "most fixed-point iterations per macro step",
    "tolerance": "relative convergence tolerance of the interface iteration",
    "force_tolerance": "absolute convergence tolerance on the interface forces",
    "relaxation": "initial (Aitken) or constant relaxation factor",
    "acceleration": "how the iteration is accelerated: Aitken or interface quasi-Newton",
    "reuse": "macro steps whose quasi-Newton pairs are reused (iqn_ils)",
    "filter_tolerance": "QR filter of the quasi-Newton pairs (iqn_ils)",
    "method": "the monolithic reference's method (DOP853, RK45: cosim's own pairs; RK23, Radau, BDF, LSODA: scipy's solve_ivp)",
    "rtol": "relative tolerance of the monolithic reference",
    "atol": "absolute tolerance of the monolithic reference",
    "max_step": "largest step of the monolithic reference",
    "output_interval": "time between recorded samples of the monolithic reference",
}


def section(section_id: str) -> Section:
    """The section ``section_id`` of :data:`SECTIONS` (``"law.NAME"`` for a law)."""
    if section_id.startswith("law."):
        return law_section(section_id[4:])
    if section_id.startswith("structure.") and section_id not in SECTIONS:
        return structure_section(section_id[10:])
    return SECTIONS[section_id]


def structure_section(name: str) -> Section:
    """The keys of ``[subsystems.NAME]`` for a plug-in structure registered
    as ``name`` (:class:`fem.StructureModel`): ``type``, the fields of its
    dataclass (unit, check and meaning from each field's metadata), then the
    keys every structure shares."""
    from cosim.scene.plugin_structure import fields_of
    from fem import STRUCTURE_MODELS
    cls = STRUCTURE_MODELS[name]
    keys = [_SUBSYSTEM_TYPE]
    for f, check in fields_of(cls):
        default = REQUIRED if f.default is dataclasses.MISSING else f.default
        keys.append(K(f.name, f.metadata.get("unit", ""), default, check,
                      f.metadata.get("doc", f"a parameter of `{cls.__name__}`")))
    taken = {k.name for k in keys}
    keys.extend(k for k in _COMMON_STRUCTURE if k.name not in taken)
    return Section("subsystems.NAME", f'type = "{name}"', tuple(keys))


def law_section(name: str) -> Section:
    """The keys of ``[contacts.NAME.law]`` for the law registered as ``name``:
    ``type`` and the fields of its dataclass."""
    from couplers import CONTACT_LAWS
    cls = CONTACT_LAWS[name]
    keys = [K("type", "", REQUIRED, "one of " + ", ".join(f'"{n}"' for n in CONTACT_LAWS),
              "the contact law")]
    for f in dataclasses.fields(cls):
        # a user's law may bring parameters of its own: their unit and meaning
        # from the field's metadata (``field(metadata={"unit": ..., "doc": ...})``)
        unit, meaning = LAW_PARAMETERS.get(f.name) or (
            f.metadata.get("unit", ""), f.metadata.get("doc", f"a parameter of `{cls.__name__}`"))
        if f.default is not dataclasses.MISSING:
            default = f.default
        else:
            default = REQUIRED
        # a field may state its range (``metadata={"check": ...}``)
        check = f.metadata.get("check", "a finite number (the law checks its range)")
        keys.append(K(f.name, unit, default, check, meaning))
    return Section("contacts.NAME.law", f'type = "{name}"', tuple(keys))


def scheme_section() -> Section:
    """The keys of ``[scheme]``: ``name``, every option of every registered
    scheme (which schemes take it in the check column) and the
    ``[scheme.NAME]`` tables."""
    from cosim.core.schemes import COUPLING_SCHEMES
    names = list(COUPLING_SCHEMES)
    keys = [K("name", "", REQUIRED, "one of " + ", ".join(f'"{n}"' for n in names),
              "the coupling scheme"),
            K("accuracy", "", None, 'in (0, 1): a number or a percentage such as "1%"',
              "the relative accuracy `cosim info` chooses a scheme and steps for "
              "(`cosim info --accuracy` wins); a run does not read it")]
    seen = {}
    for n in names:
        for opt, spec in COUPLING_SCHEMES[n].options.items():
            seen.setdefault(opt, []).append((n, spec))
    for opt, specs in seen.items():
        takers = [n for n, _ in specs]
        spec = specs[0][1]
        unit = "s" if spec.rule.endswith(" s") else ("N" if spec.rule.endswith(" N") else "")
        rule = spec.rule[:-2] if unit else spec.rule
        if opt == "macro_step":
            default = Varies("required by every scheme that takes it")
        else:
            default = _scheme_default(specs)
        keys.append(K(opt, unit, default, f"{rule} ({', '.join(takers)})",
                      SCHEME_OPTIONS[opt]))
    keys.append(K("SCHEME", "", None, "a table of options of the scheme named SCHEME",
                  "options that apply only when that scheme runs (`[scheme.monolithic]`)"))
    return Section("scheme", "", tuple(keys))


def _scheme_default(specs: list) -> object:
    """The default of a scheme option that several schemes take: their common
    default, or, where they differ, a :class:`Varies` that gives each
    scheme's (``(name, OptionSpec)`` pairs in registry order)."""
    defaults = [spec.default for _, spec in specs]
    if all(_same(d, defaults[0]) for d in defaults):
        return defaults[0]
    groups: list[tuple[object, list[str]]] = []
    for n, spec in specs:
        for d, members in groups:
            if _same(d, spec.default):
                members.append(n)
                break
        else:
            groups.append((spec.default, [n]))
    return Varies(", ".join(f"{_default_text(d)} ({', '.join(m)})" for d, m in groups))


def _same(a, b) -> bool:
    return type(a) is type(b) and repr(a) == repr(b)


# ----------------------------------------------------------------- render
def _default_text(default) -> str:
    if default is REQUIRED:
        return "required"
    if isinstance(default, Varies):
        return default.text
    if default is None:
        return "not set"
    if isinstance(default, bool):
        return "`true`" if default else "`false`"
    if isinstance(default, str):
        return f'`"{default}"`'
    if isinstance(default, (tuple, list)):
        return "`[" + ", ".join(f"{x:g}" if isinstance(x, float) else repr(x)
                                for x in default) + "]`"
    if isinstance(default, dict):
        return "`{}`"
    if isinstance(default, float):
        return "`inf`" if math.isinf(default) else f"`{default:g}`"
    return f"`{default}`"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").strip()


def _ordered_sections() -> list[Section]:
    out, seen = [], set()
    for sid, sec in SECTIONS.items():
        if id(sec) in seen:
            continue
        seen.add(id(sec))
        out.append(sec)
        if sid == "top":
            out.append(scheme_section())
        if sid == "contact":
            from couplers import CONTACT_LAWS
            out.extend(law_section(n) for n in CONTACT_LAWS)
    return out


def reference_markdown() -> str:
    """The scene file's keys as MyST Markdown, for the documentation.

    One ``##`` heading per table of a scene file (``## [scheme]``,
    ``## [contacts.NAME.law] with type = "hertz"``) and under it a pipe table
    with the columns key, unit, default, check and meaning, made from the
    same table the loader reads (:data:`SECTIONS`, the scheme registry and
    the contact-law registry).

    Returns
    -------
    str
        Markdown without trailing whitespace, ending with one newline.
    """
    lines = []
    for sec in _ordered_sections():
        lines += [f"## {sec.title}", "", "| key | unit | default | check | meaning |",
                  "| --- | --- | --- | --- | --- |"]
        for k in sec.keys:
            lines.append("| " + " | ".join(_cell(c) for c in (
                f"`{k.name}`", k.unit or "-", _default_text(k.default), k.check, k.meaning))
                + " |")
        lines.append("")
    return "\n".join(line.rstrip() for line in lines).rstrip() + "\n"
