"""One rule for building a settings dataclass from a section of the configuration.

Every section of ``config.yaml`` is read by the package through a frozen dataclass
(``calibration``, ``reconstruction``, ``cell``, ``tracking``, ``volume``, ``stress``, ``report``,
``score``, ``simulation`` and its ``load_frame``), built by that dataclass's ``from_dict``, and
each ``from_dict`` calls :func:`section_from_dict` (or :func:`section_dict`, when it converts
values first). The kit design (``kit.yaml``, :mod:`triaxtrack.kit_design`) is read by the same
rule, section by section (its keys have no defaults but a few optional ones: a key it needs and
the file leaves out is an error too):

* **An unknown key is an error**: ValueError naming the section, the key, the key meant for a
  near miss and the known keys (``tracking: unknown key 'gates' (did you mean 'gate'?); known
  keys: ...``). A typo is never silently ignored. (``test.yaml`` is different: a recorder may
  write more, so its extra keys are a warning, :mod:`triaxtrack.testfolder`.)
* **The dataclass is the single source of defaults**: a key left out takes the field's
  default. ``config/config.yaml`` writes every key out for the reader; its values are the
  fields' defaults (``tests/test_config_errors.py`` checks that they agree).
* **None is a value**, passed to the field as given, not "use the default". The config files
  write ``null`` only for fields whose default is None, where it means "none" or "the kit's"
  (``tracking.step_s``, ``stress.search_s``, ``simulation.occluder_z_mm``, ...), and the
  workflow's schema allows ``null`` nowhere else. A whole section that is None (an empty
  ``score:`` in YAML) is an empty one: every field its default.
* **A section may feed several dataclasses** (``reconstruction``: ``SfmConfig`` and
  ``TriangulationConfig``): each takes its own fields and accepts the others' keys, named in
  ``also`` (usually :func:`field_names` of the sibling dataclasses); a key known to none of
  them is an error.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import fields
from typing import TYPE_CHECKING, Any, TypeVar

from triaxtrack.errors import did_you_mean

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

    T = TypeVar("T", bound=DataclassInstance)

__all__ = ["field_names", "section_dict", "section_from_dict"]


def field_names(*classes: type[DataclassInstance]) -> tuple[str, ...]:
    """The names of the dataclasses' ``__init__`` fields, in order, each once."""
    names = [f.name for cls in classes for f in fields(cls) if f.init]
    return tuple(dict.fromkeys(names))


def section_dict(d: Mapping[str, Any] | None, section: str, known: Iterable[str]) -> dict[str, Any]:
    """A copy of the config section ``d`` (None: empty) whose keys are all in ``known``;
    ValueError naming ``section``, each unknown key (with the key meant, for a near miss) and
    the known keys, or saying that ``d`` is not a mapping."""
    if d is None:
        return {}
    if not isinstance(d, Mapping):
        raise ValueError(f"{section}: must be a mapping of settings, not {d!r}")
    known = sorted(set(known))
    unknown = [str(key) for key in d if key not in known]
    if unknown:
        named = []
        for key in unknown:
            hint = did_you_mean(key, known)
            named.append(f"{key!r}" + (f" ({hint[2:]})" if hint else ""))
        plural = "s" if len(unknown) > 1 else ""
        raise ValueError(f"{section}: unknown key{plural} {', '.join(named)}; known keys: {', '.join(known)}")
    return dict(d)


def section_from_dict(
    cls: type[T], d: Mapping[str, Any] | None, section: str, *, also: Iterable[str] = ()
) -> T:
    """``cls`` (a dataclass) from the config section ``d``: its fields from ``d``'s keys, the
    rest their defaults. ``also``: keys of the section that other dataclasses read (accepted,
    left out). ValueError (:func:`section_dict`) for a key that is neither."""
    names = field_names(cls)
    items = section_dict(d, section, (*names, *also))
    return cls(**{key: value for key, value in items.items() if key in names})
