"""The certificate report: its file (checked, written atomically), comparison with a previous
report, and declared known deviations (waivers). Stdlib only, so the plugin can check every
option at configure time without importing the engine.

A report is JSON: ``{"format": FORMAT, "profile", "backend", "certificates": [...],
"waivers": [...], "compare": {...} or null}``; each certificate is a
:class:`~peclet_verify.search.PropertyResult` as a dict plus ``test`` (its node id) and
``waived`` (the reason, or null).
"""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass

from . import registry as REG

__all__ = ["FORMAT", "check_report_path", "load_report", "write_report", "TOLERANCES",
           "tolerance_for", "compare", "Waiver", "load_xfails", "find_waiver"]

FORMAT = "peclet-certificates/1"
# The lists below are views of the one registry (:mod:`peclet_verify.registry`).
#: Property ids (an xfails file may name one for all of its certificates).
PROPERTY_NAMES = REG.properties()
#: The certificates :mod:`peclet_verify.geometry.suite` ships (they certify the backend).
SUITE_CERTIFICATES = REG.titles(scope="suite")
#: The certificates this repository's ``properties/`` adds (they certify peclet itself).
REPO_CERTIFICATES = REG.titles(scope="repo")
#: The DEM and mechanics families' certificates (:mod:`peclet_verify.dem.suite`, :mod:`peclet_verify.mechanics.suite`, any DEM
#: backend) and their properties.
DEM_CERTIFICATES = REG.titles(scope="dem")
DEM_PROPERTY_NAMES = REG.properties(scope="dem")
#: The mass-property family's certificate (:mod:`peclet_verify.mass.suite`).
MASS_CERTIFICATES = REG.titles(scope="mass")
#: The impact family's certificates (:mod:`peclet_verify.impact.suite`: Chung & Ooi 1-8).
IMPACT_CERTIFICATES = REG.titles(scope="impact")
#: Names an xfails file may use: a certificate's name or a property's (all its certificates).
KNOWN_CERTIFICATES = REG.known_names()


class ReportFileError(ValueError):
    """A report, baseline or xfails file that cannot be used; the message names the file."""


# ---------------------------------------------------------------------------- the report file
def _looks_like_report(data) -> bool:
    if not isinstance(data, dict) or not isinstance(data.get("certificates"), list):
        return False
    if data.get("format") != FORMAT and not {"profile", "backend"} <= set(data):
        return False  # reports written before FORMAT existed have these keys
    return all(isinstance(c, dict) and isinstance(c.get("name"), str)
               and isinstance(c.get("status"), str) for c in data["certificates"])


def load_report(path, what="report") -> dict:
    """The report at ``path``; :class:`ReportFileError` (naming the file) if it is missing,
    unreadable, not JSON, or not a peclet certificate report."""
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise ReportFileError(f"{what} {path}: no such file") from None
    except IsADirectoryError:
        raise ReportFileError(f"{what} {path}: is a directory, not a report") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ReportFileError(f"{what} {path}: not a peclet certificate report "
                              f"({type(exc).__name__}: {exc})") from None
    if not _looks_like_report(data):
        raise ReportFileError(f"{what} {path}: not a peclet certificate report (JSON without "
                              f"a 'certificates' list of named results)")
    return data


def check_report_path(path) -> str:
    """The absolute path if ``path`` can receive a report, else :class:`ReportFileError`.

    Refused: a directory, a path under a file, an unwritable location, an existing read-only
    file, and any existing file that is not a peclet report (it is never overwritten)."""
    from peclet.core.files import check_writable_path
    from peclet.core.validation import PecletArgumentError
    try:
        p = check_writable_path(path, "--peclet-report")
    except PecletArgumentError as exc:
        raise ReportFileError(str(exc)) from None
    # mode bits too, not only os.access: a superuser may write anywhere, but a file or a
    # directory nobody may write to says "do not write here"
    probe = os.path.dirname(p)
    while not os.path.exists(probe):
        probe = os.path.dirname(probe)
    if not os.stat(probe).st_mode & 0o222:
        raise ReportFileError(f"--peclet-report {path}: {probe} is read-only")
    if os.path.exists(p):
        if not os.access(p, os.W_OK) or not os.stat(p).st_mode & 0o222:
            raise ReportFileError(f"--peclet-report {path}: the existing file is read-only")
        try:
            load_report(p)
        except ReportFileError:
            raise ReportFileError(f"--peclet-report {path}: the file exists and is not a "
                                  f"peclet certificate report; refusing to overwrite it") from None
    return p


def _strict_json(value):
    """``value`` with every non-finite float spelled as a string ("inf", "nan"): the report
    stays strict JSON (a figure of ``-inf`` is ``null`` already, see ``PropertyResult``)."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if isinstance(value, dict):
        return {str(k): _strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict_json(v) for v in value]
    return value


def write_report(path, data) -> str:
    """Write ``data`` (with ``format`` set) as strict JSON to ``path`` atomically."""
    from peclet.core.files import atomic_write

    def write(tmp):
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(_strict_json(dict(data, format=FORMAT)), f, indent=2, allow_nan=False)
    return atomic_write(path, write)


# ---------------------------------------------------------------------------- comparison
#: How much worse a figure may get before ``--peclet-compare`` fails the run, by the figure's
#: name (prefix): (factor, floor), from :data:`peclet_verify.registry.FIGURES` (which says how
#: the badness of a figure is judged).
TOLERANCES = {label: (factor, floor) for label, (_, factor, floor) in REG.FIGURES.items()}
DEFAULT_TOLERANCE = (10.0, 1e-12)


def tolerance_for(figure_name: str):
    """(factor, floor) for a figure (see :data:`TOLERANCES`)."""
    for prefix, tol in TOLERANCES.items():
        if (figure_name or "").startswith(prefix):
            return tol
    return DEFAULT_TOLERANCE


def _badness(cert):
    w = cert.get("worst")
    if w is None:
        return None
    return -w if cert.get("worse") == "min" else w


def _fig(cert):
    w = cert.get("worst")
    return "-" if w is None else f"{w:.3g}"


def compare(previous: dict, certificates: list):
    """Compare this run's ``certificates`` (report dicts) with a ``previous`` report.

    Returns ``(regressions, lines)``: the names that regressed (a certificate that passed and
    now fails without a waiver, or a figure worse than :data:`TOLERANCES` allows) and a
    side-by-side table as text lines. Certificates only in one of the two reports are listed,
    not judged."""
    before = {c["name"]: c for c in previous.get("certificates", [])}
    now = {c["name"]: c for c in certificates}
    head = (f"{'certificate':<40} {'before':<8} {'figure':>10}   {'now':<8} {'figure':>10}  "
            f"{'allowed':<16} verdict")
    lines, regressions = [head, "-" * len(head)], []
    for name in list(before) + [n for n in now if n not in before]:
        b, c = before.get(name), now.get(name)
        if b is None or c is None:
            verdict, allowed = ("new" if b is None else "not run"), ""
        else:
            factor, floor = tolerance_for(c.get("worst_name", ""))
            allowed = f"x{factor:g} (floor {floor:g})"
            bb, bc = _badness(b), _badness(c)
            failed_now = c["status"] == "failed" and not c.get("waived")
            if b["status"] == "passed" and failed_now:
                verdict = "REGRESSED (passed, now fails)"
            elif bb is not None and bc is not None and math.isfinite(bb) and \
                    bc > factor * max(bb, floor):
                verdict = f"REGRESSED (figure x{bc / max(bb, floor, 1e-300):.3g})"
            elif bb is not None and bc is None and c["status"] == "failed":
                verdict = "REGRESSED (no figure now)"
            else:
                verdict = "ok"
            if verdict.startswith("REGRESSED"):
                regressions.append(name)
        lines.append(f"{name[:40]:<40} {(b or {}).get('status', '-'):<8} "
                     f"{_fig(b) if b else '-':>10}   {(c or {}).get('status', '-'):<8} "
                     f"{_fig(c) if c else '-':>10}  {allowed:<16} {verdict}")
    return regressions, lines


# ---------------------------------------------------------------------------- waivers
@dataclass(frozen=True)
class Waiver:
    """A declared known deviation: certificate ``name`` (a certificate's name, or a property
    name such as ``sign_agreement`` for all of its certificates) may fail for ``reason``;
    with ``kinds``, only when the counterexample has a leaf of one of those kinds."""

    name: str
    reason: str
    kinds: tuple = ()

    def matches(self, cert: dict) -> bool:
        name = cert.get("name", "")
        prop = (cert.get("details") or {}).get("property", "")
        if self.name not in (name, prop) and not name.startswith(self.name + " [shard"):
            return False
        text = cert.get("counterexample", "")
        return not self.kinds or any(f"'{k}'" in text for k in self.kinds)

    def to_dict(self) -> dict:
        return {"certificate": self.name, "reason": self.reason, "kinds": list(self.kinds)}


def _parse_xfails(path):
    with open(path, "rb") as f:
        raw = f.read()
    if str(path).endswith(".toml"):
        import tomllib
        return tomllib.loads(raw.decode("utf-8"))
    return json.loads(raw.decode("utf-8"))


def load_xfails(path, known) -> list:
    """The waivers declared in ``path`` (TOML if it ends in ``.toml``, else JSON)::

        ["sign_agreement"]                      # or JSON {"sign_agreement": {...}}
        reason = "upstream superquadric sign bug"
        kinds = ["superquadric"]                # optional

    (a bare string value is the reason). Every name must be in ``known``; anything else
    (a missing or unparsable file, an unknown certificate, a missing reason) is a
    :class:`ReportFileError` naming the file."""
    try:
        data = _parse_xfails(path)
    except FileNotFoundError:
        raise ReportFileError(f"--peclet-xfails {path}: no such file") from None
    except Exception as exc:  # tomllib / json / decoding errors: one line naming the file
        raise ReportFileError(f"--peclet-xfails {path}: cannot parse it "
                              f"({type(exc).__name__}: {exc})") from None
    if not isinstance(data, dict) or not data:
        raise ReportFileError(f"--peclet-xfails {path}: expected a table of certificate name "
                              f"-> reason, got {type(data).__name__}")
    waivers = []
    for name, entry in data.items():
        if name not in known:
            raise ReportFileError(f"--peclet-xfails {path}: unknown certificate {name!r} "
                                  f"(known: {', '.join(sorted(known))})")
        if isinstance(entry, str):
            entry = {"reason": entry}
        reason = entry.get("reason") if isinstance(entry, dict) else None
        kinds = entry.get("kinds", []) if isinstance(entry, dict) else None
        if not isinstance(reason, str) or not reason.strip():
            raise ReportFileError(f"--peclet-xfails {path}: {name!r} needs a non-empty reason")
        if not isinstance(kinds, list) or not all(isinstance(k, str) and re.fullmatch(
                r"[a-z_]+", k) for k in kinds):
            raise ReportFileError(f"--peclet-xfails {path}: {name!r}: kinds must be a list of "
                                  f"leaf kind names")
        unknown = set(entry) - {"reason", "kinds"}
        if unknown:
            raise ReportFileError(f"--peclet-xfails {path}: {name!r}: unknown key(s) "
                                  f"{sorted(unknown)}")
        waivers.append(Waiver(name, reason.strip(), tuple(kinds)))
    return waivers


def find_waiver(waivers, cert: dict):
    """The first waiver matching a failed certificate ``cert``, or None."""
    if cert.get("status") != "failed":
        return None
    return next((w for w in waivers if w.matches(cert)), None)
