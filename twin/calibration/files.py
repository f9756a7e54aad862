"""Calibrations as named objects: the folder of calibration files, how one is found by name or
path and checked, and how a new one is written (with its provenance, never half-written, never
over a file the project did not write).

A calibration file records what the twin needs to run it and what it came from: its breakage
map (``"dem"``: the DEM laws of twin.calibration.dem_map; ``"mineralogy"``: the hardness/texture
map of twin.calibration.breakage_map), the effects, size grid, mixers and mill it was fitted
with, the coefficients the effects read, the fitted mill values, each fitted number with why
it is not derivable, the data and the command.
"""

from __future__ import annotations

import hashlib
import json
import math
import platform
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from ..atomic import json_text, write_text_atomically
from ..errors import FastCalibrationWarning, TwinInputError, close_matches
from .model_code import model_identity
from .record_checks import check_data, check_fields, check_fitted, check_law

#: The folder of shipped calibration files, one per name (``<name>.json``).
CALIBRATION_DIR = Path(__file__).resolve().parent / "files"
TABLE_CALIBRATION_PATH = CALIBRATION_DIR / "table.json"
DEM_CALIBRATION_PATH = CALIBRATION_DIR / "dem.json"
#: What ``Twin`` and scenes run unless told otherwise: the mechanistic chain (MISSION.md s3-4).
DEFAULT_CALIBRATION = "dem"
#: The marker and version of a calibration file written by grindtwin.
FILE_FORMAT = "grindtwin-calibration"
FORMAT_VERSION = 2
BREAKAGE_MAPS = ("dem", "mineralogy")
#: Effects that only delay or filter what is measured (an analyser's dead time): a calibration
#: fitted to steady states does not depend on them, so a scene may add them freely.
MEASUREMENT_EFFECTS = ("sensor_delay",)
#: What every mention of a --fast calibration says (:attr:`Calibration.fast`).
FAST_LABEL = "; made with --fast: a check of the machinery on a few particles, not a calibration"
#: Relative margin past the fitted ores' range before an input is called an extrapolation (the
#: reference ores' own values, recomputed, may differ from the record's in the last digits).
EXTRAPOLATION_TOL = 1e-9
#: A mineral more than this many wt% points above its largest share in the ores a calibration was fitted on
#: is noted: the maps read a mineral only through the ore's mass-weighted hardness, modulus and density (and
#: its clay and soft groups), untested on an ore made of it (35 wt% calcite, 5 in the reference ores at most,
#: ground 26 % cheaper than its Bond work index says, and a mineral absent from them, as bornite, looked fitted);
#: the reference ores' own main minerals differ by this much and more from ore to ore.
MINERAL_EXTRAPOLATION_WT_PCT = 5.0
REQUIRED_KEYS = ("name", "breakage_map", "effects", "size_grid", "n_mixers", "mill", "coefficients", "mills")


@dataclass(frozen=True, eq=False)
class Calibration:
    """One calibration: its record (the file's content), name, file and SHA-256 of the file (of
    the record's JSON, keys sorted, for a record given as a dict; ``None`` for a calibration made
    in memory, e.g. during a fit)."""

    record: dict = field(repr=False)
    path: Path | None = None
    sha256: str | None = None

    @property
    def name(self) -> str:
        return self.record["name"]

    @property
    def breakage_map(self) -> str:
        return self.record["breakage_map"]

    @property
    def coefficients(self) -> dict:
        return self.record["coefficients"]

    @property
    def effects(self) -> list:
        return list(self.record["effects"])

    @property
    def size_grid(self) -> dict:
        return dict(self.record["size_grid"])

    @property
    def mill(self) -> str:
        return self.record["mill"]

    @property
    def n_mixers(self) -> int:
        return int(self.record["n_mixers"])

    @property
    def fitted(self) -> dict:
        """Fitted number -> {"value", "why_not_derivable"}."""
        return dict(self.record.get("fitted", {}))

    def grid(self):
        from ..sizes import SizeGrid

        return SizeGrid(**self.size_grid)

    def texture_notes(self, ores) -> list[str]:
        """What this calibration's breakage map leaves out of ``ores`` (those it maps): the dem map
        reads each ore's hardness index, elastic modulus and density (twin.calibration.dem_map),
        not its texture, so a user's ore (one that is not the reference type of its name) gets a
        note; none for the reference ores or the mineralogy map, which reads texture too."""
        if self.breakage_map != "dem":
            return []
        from ..ore import reference_ores

        refs = reference_ores()
        users = [o.name for o in ores if refs.get(o.name) != o]
        if not users:
            return []
        return [f"the dem calibration's breakage map reads the hardness index, elastic modulus and density of "
                f"ore {', '.join(users)}, not its texture (the textural index; twin.calibration.dem_map): the "
                "table calibration (--calibration table) maps texture too"]

    def extrapolation_notes(self, ores) -> list[str]:
        """The ores of ``ores`` whose inputs to this calibration's breakage map lie outside those of
        the ores it was fitted on, so their breakage is the map's extrapolation: the dem map's energy
        group Pi (twin.calibration.dem_map s1: its law is the bonded model's, the strength index F(M)
        is untested there) and the hardness index and Young's modulus F reads, the mineralogy map's
        hardness and textural indices; both maps' density, and any mineral held well above its largest
        share in those ores (:data:`MINERAL_EXTRAPOLATION_WT_PCT`)."""
        from ..ore import reference_ores

        refs = reference_ores()
        if self.breakage_map == "dem":
            from .strength import energy_group

            law = self.record["law"]
            fitted = law["ln_energy_group"]
            names = list(fitted)
            # Pi and the two properties its strength index F reads: a 70 % pyrite ore (hardness 12.8 GPa against
            # 4.4-9.65) had a Pi inside the range, and no note
            inputs = {"energy group Pi": (lambda o: energy_group(o, law["reference"]),
                                          [math.exp(v) for v in fitted.values()], ""),
                      "hardness index": (lambda o: o.hardness_index_gpa,
                                         [refs[n].hardness_index_gpa for n in names], " GPa"),
                      "Young's modulus": (lambda o: o.youngs_gpa, [refs[n].youngs_gpa for n in names], " GPa")}
        elif "fit" not in self.record:  # a record being fitted (grindtwin calibrate --map mineralogy): no range yet
            return []
        else:
            names = list(self.record["fit"]["ores"])
            inputs = {"hardness index": (lambda o: o.hardness_index_gpa,
                                         [refs[n].hardness_index_gpa for n in names], " GPa"),
                      "textural index": (lambda o: o.textural_index, [refs[n].textural_index for n in names], "")}
        inputs["density"] = (lambda o: o.density_t_m3, [refs[n].density_t_m3 for n in names], " t/m3")
        notes = []
        for ore in ores:
            for mineral, wt in sorted(ore.wt_pct.items(), key=lambda kv: -kv[1]):
                most = max(refs[n].wt_pct.get(mineral, 0.0) for n in names)
                if wt > most + MINERAL_EXTRAPOLATION_WT_PCT:
                    notes.append(f"ore {ore.name} holds {wt:.3g} wt% {mineral}, more than the {most:.3g} wt% at most of "
                                 f"the ores the {self.name} calibration was fitted on ({', '.join(names)}): the breakage "
                                 "map reads it only through the ore's mean hardness, modulus and density, untested on "
                                 "such an ore; its breakage is the map's extrapolation")
            for what, (of, values, unit) in inputs.items():
                v, lo, hi = of(ore), min(values), max(values)
                if not lo * (1 - EXTRAPOLATION_TOL) <= v <= hi * (1 + EXTRAPOLATION_TOL):
                    notes.append(f"ore {ore.name}'s {what} {v:.3g}{unit} lies outside the {lo:.3g}-{hi:.3g}{unit} "
                                 f"of the ores the {self.name} calibration was fitted on ({', '.join(names)}): its "
                                 "breakage is the map's extrapolation")
        return notes

    def fit_notes(self) -> list[str]:
        """That the fit's optimizer did not converge, if it did not: the file's numbers are then its
        last step, not a fit (``grindtwin calibrate`` says so when it writes the file; a twin built
        on the file says it with every answer)."""
        opt = self.record.get("fit", {}).get("optimizer", {})
        if opt.get("success", True):
            return []
        return [f"calibration {self.name!r}: its fit did not converge when it was made "
                f"({opt.get('message', 'no message recorded')}), so its numbers are the optimizer's last step, "
                "not a fit; refit it with `grindtwin calibrate`"]

    def ore_notes(self, ores) -> list[str]:
        """What a steady state cannot show of ``ores``: :meth:`texture_notes` and
        :meth:`extrapolation_notes`."""
        return self.texture_notes(ores) + self.extrapolation_notes(ores)

    def breakage(self, ore):
        """Breakage parameters of an ore by this calibration's map."""
        if self.breakage_map == "dem":
            from .dem_map import dem_breakage

            if self.path is not None and (self.path, self.sha256) not in _LAWS_CHECKED:  # once per file
                check_law(self.record, str(self.path))
                _LAWS_CHECKED.add((self.path, self.sha256))
            return dem_breakage(ore, self.record["law"], self.coefficients["dem_capture_scale"])
        from .breakage_map import mineralogy_breakage

        return mineralogy_breakage(ore, self.coefficients)

    @property
    def fast(self) -> bool:
        """Its DEM step ran ``--fast`` (``grindtwin calibrate --fast``, or ``--from`` such a file):
        a check that the chain runs, on a few particles, not a calibration to predict with. (With
        ``--from`` a full DEM step, ``--fast`` only cuts the bootstrap replicates.)"""
        return bool(self.record.get("dem", {}).get("settings", {}).get("fast"))

    def label(self) -> str:
        where = str(self.path) if self.path else "in memory"
        sha = f", sha256 {self.sha256[:12]}" if self.sha256 else ""
        return f"{self.name!r} ({where}{sha}{FAST_LABEL if self.fast else ''})"

    def identity(self) -> dict:
        """What a run records of the calibration it ran: name, file, hash, the command (and
        ``fast``: true for a --fast check, see :attr:`fast`)."""
        return {"name": self.name, "path": _shown_path(self.path), "sha256": self.sha256,
                "breakage_map": self.breakage_map,
                "command": self.record.get("provenance", {}).get("command"),
                **({"fast": True} if self.fast else {})}

    def mismatch(self, effects, grid, mill=None, mixer_fracs=None) -> list[str]:
        """What differs between a model's effects and size grid and this calibration's (empty:
        none), with ``mill`` its fitted values (:meth:`mill_values_mismatch`) and with ``mixer_fracs``
        its mixers (:meth:`mixers_mismatch`).
        Measurement effects (:data:`MEASUREMENT_EFFECTS`) are not compared."""
        mine = [e for e in self.effects if e not in MEASUREMENT_EFFECTS]
        theirs = [e for e in effects if e not in MEASUREMENT_EFFECTS]
        out = []
        if sorted(mine) != sorted(theirs):
            out.append(f"effects {sorted(theirs)} differ from the effects of calibration {self.name!r} "
                       f"{sorted(mine)} (missing {sorted(set(mine) - set(theirs))}, extra "
                       f"{sorted(set(theirs) - set(mine))})")
        g = self.size_grid
        theirs_g = {"top_um": float(grid.top_um), "ratio": float(grid.ratio), "count": int(grid.count),
                    "scheme": grid.scheme}
        # a record without a scheme predates the second-order discretisation: Austin's form
        same_scheme = g.get("scheme", "austin") == grid.scheme
        if not same_scheme or not all(math.isclose(float(g[k]), float(theirs_g[k]), rel_tol=1e-9)
                                      for k in ("top_um", "ratio", "count")):
            out.append(f"size grid {theirs_g} differs from the grid of calibration {self.name!r} {g}")
        return out + self.mill_values_mismatch(mill) + self.mixers_mismatch(mill, mixer_fracs)

    def mill_values_mismatch(self, mill) -> list[str]:
        """What differs between ``mill`` (a twin.Mill) and the values this calibration fitted for
        it (record ``mills``) when it is the calibration's own mill by name (empty: none): a Mill
        made without them (twin.mill.LAB, ``get_mill("lab")`` without the record) ran the
        calibration's breakage and coefficients with another grate, discharge and power factor, with
        no word. A preset name takes them (twin.mill.get_mill): nothing to compare."""
        if getattr(mill, "name", None) != self.mill:
            return []
        from ..mill import MILLS

        fitted = self.record["mills"].get(self.mill, {})
        off = [f"{k} {getattr(mill, k):.6g} (fitted {v:.6g})" for k, v in fitted.items()
               if not math.isclose(float(getattr(mill, k)), float(v), rel_tol=1e-12)]
        out = [f"mill {self.mill!r} has {', '.join(off)}: calibration {self.name!r} fitted these values of its "
               f"{self.mill!r} mill (its record's mills.{self.mill}); a Mill of it takes them from "
               f"twin.get_mill({self.mill!r}, calibration.record)"] if off else []
        model = MILLS[self.mill].power_model if self.mill in MILLS else mill.power_model
        if mill.power_model != model:  # the fitted power factor corrects the model it was fitted with
            out.append(f"mill {self.mill!r} has power_model {mill.power_model!r}: calibration {self.name!r} fitted its "
                       f"power factor ({mill.power_factor:.4g}) to the power of {model!r}")
        return out

    def mixers_mismatch(self, mill, mixer_fracs) -> list[str]:
        """What differs between a twin's mixers (``mixer_fracs``: their shares of the hold-up, in
        series) and the calibration's ``n_mixers`` equal ones (empty: none, or nothing to compare).
        The fitted mill values (record ``mills``) of the calibration's mill (record ``mill``) were
        fitted with those mixers, so a twin of that mill (``mill``: a twin.Mill or a preset name,
        compared by name) with another number or unequal shares runs them outside their fit. On
        another mill the mixers are that mill's own (its breakage is scaled to it, twin.scaleup):
        not compared."""
        name = getattr(mill, "name", mill)
        if name is None or mixer_fracs is None or name != self.mill:
            return []
        total = float(sum(mixer_fracs))
        shares = [float(f) / total for f in mixer_fracs]
        n = len(shares)
        why = (f"calibration {self.name!r} fitted its {self.mill!r} mill's values (its record's mills.{self.mill}) "
               f"with n_mixers = {self.n_mixers} equal mixers")
        if n != self.n_mixers:
            return [f"n_mixers = {n} on the {name!r} mill differs from the calibration's: {why}"]
        if not all(math.isclose(f, 1.0 / n, rel_tol=1e-9) for f in shares):
            return [f"mixer_volume_fracs {[round(f, 4) for f in shares]} on the {name!r} mill are not the equal "
                    f"shares of the calibration: {why}"]
        return []

    def with_values(self, coefficients: dict | None = None, mills: dict | None = None, **record) -> "Calibration":
        """A copy in memory with coefficients / mill values (and other record keys) replaced."""
        rec = dict(self.record)
        if coefficients is not None:
            rec["coefficients"] = {**self.coefficients, **coefficients}
        if mills is not None:
            rec["mills"] = {**self.record["mills"], **{k: {**self.record["mills"].get(k, {}), **v}
                                                       for k, v in mills.items()}}
        rec.update(record)
        return Calibration(rec)


def _shown_path(path) -> str | None:
    """A shipped calibration's path inside the package (the same on every machine), else the file's."""
    if path is None:
        return None
    path = Path(path)
    if path.parent.resolve() == CALIBRATION_DIR.resolve():
        return f"twin/calibration/files/{path.name}"
    return str(path)


def base_record(name: str, breakage_map: str, description: str) -> dict:
    """The head of a new calibration record: what it is, and the model it is fitted with (the
    twin's default effects, size grid and mixers, the lab mill of MISSION.md's table)."""
    import inspect

    from ..sizes import SizeGrid
    from ..twin import DEFAULT_EFFECTS, Twin

    g = SizeGrid()
    n_mixers = inspect.signature(Twin).parameters["n_mixers"].default
    return {"format": FILE_FORMAT, "format_version": FORMAT_VERSION, "name": name, "description": description,
            "breakage_map": breakage_map, "effects": list(DEFAULT_EFFECTS),
            "size_grid": {"top_um": float(g.top_um), "ratio": float(g.ratio), "count": int(g.count),
                          "scheme": g.scheme},
            "n_mixers": n_mixers, "mill": "lab", "model_code": model_identity()}


def shipped_names() -> list[str]:
    """Names of the shipped calibrations (the files of :data:`CALIBRATION_DIR`)."""
    return sorted(p.stem for p in CALIBRATION_DIR.glob("*.json"))


def check_record(record: dict, where: str, law: bool = True, data: bool = True) -> dict:
    """The record if it is a calibration of this format whose fields have their types and whose
    numbers are those it was fitted to (:func:`check_fields`, :func:`check_fitted`, with ``data``
    :func:`check_data`: the reference table it was fitted to is the table now, and with ``law``
    :func:`check_law`), else TwinInputError naming the file, the field, its value and what is
    allowed: a hand-edited or truncated file is refused, not run (a file's content digest too, when it
    is read: :func:`check_content`). (A file's laws are checked
    when its breakage map first runs, :meth:`Calibration.breakage`: the refit needs numpy, which
    the surrogate's answer does not load.)"""
    if not isinstance(record, dict) or record.get("format") != FILE_FORMAT:
        raise TwinInputError(f"{where} is not a grindtwin calibration file (its 'format' must be "
                             f"{FILE_FORMAT!r}); make one with `grindtwin calibrate`.")
    if record.get("format_version") != FORMAT_VERSION:
        raise TwinInputError(f"{where} has format version {record.get('format_version')!r}; this code reads "
                             f"version {FORMAT_VERSION}. Regenerate it with `grindtwin calibrate`.")
    missing = [k for k in REQUIRED_KEYS if k not in record]
    if missing:
        raise TwinInputError(f"{where} lacks the calibration field(s) {missing}.")
    if record["breakage_map"] not in BREAKAGE_MAPS:
        raise TwinInputError(f"The 'breakage_map' of {where} must be one of {BREAKAGE_MAPS}. "
                             f"Got {record['breakage_map']!r}.")
    if record["breakage_map"] == "dem":
        absent = [k for k in ("law", "dem") if k not in record]
        if absent:
            raise TwinInputError(f"{where} has breakage_map 'dem' but lacks {absent} (the DEM laws and the DEM "
                                 "step they are fitted to).")
    check_fields(record, where)
    check_fitted(record, where)
    if data:
        check_data(record, where)
    if record["breakage_map"] == "dem" and law:
        check_law(record, where)
    return record


def content_digest(record: dict, strict: bool = True) -> str:
    """The SHA-256 of a record's content as JSON (keys sorted), its ``content_sha256`` left out, as it is
    written (:func:`twin.atomic.json_text`: an undefined number null). ``strict=False``: as a file written
    before that recorded it (NaN, Infinity as those tokens), which one holding such a number still carries."""
    body = {k: v for k, v in record.items() if k != "content_sha256"}
    text = json.dumps(json.loads(json_text(body) if strict else json.dumps(body)), sort_keys=True,
                      separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def content_digests(record: dict) -> tuple[str, str]:
    """The digests a record grindtwin wrote may carry (:func:`content_digest`, strict JSON or not)."""
    return content_digest(record), content_digest(record, strict=False)


def check_content(record: dict, where: str) -> None:
    """A record is what grindtwin wrote (its ``content_sha256``, :func:`write_calibration`): an edit the field
    checks (:func:`check_record`) cannot see (a coefficient x3 in all its copies, the effects list, the grid, the reported fit) ran
    with exit 0 and other numbers (P80 72.6 um for 203.6). A record without the field predates it."""
    recorded = record.get("content_sha256")
    if recorded is not None and recorded not in content_digests(record):
        from .model_code import refit_command

        check_data(record, where)  # an edit these name says what it changed (deferred on a read: run now)
        if record["breakage_map"] == "dem":
            check_law(record, where)
        raise TwinInputError(f"{where} was changed after grindtwin wrote it (its content no longer matches its "
                             f"content_sha256): a calibration's numbers are made by a command, not typed in. Make a "
                             f"new one (`{refit_command(record)}`), or restore the file.")


_LOADED: dict = {}
#: (path, sha256) of the files whose content digest was checked.
_CONTENT_CHECKED: set = set()
#: (path, sha256) of the files whose DEM laws were checked against their DEM step.
_LAWS_CHECKED: set = set()


def read_calibration(path: Path, check_table: bool = True) -> Calibration:
    """A calibration file, checked; cached by path and content hash. The reference table it was
    fitted to is compared with the table's current hash at every read (:func:`check_data`; the
    table is small); ``check_table=False`` skips that (a caller that reuses only a file's DEM step, which
    does not read the table)."""
    path = Path(path).resolve()
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise TwinInputError(f"Cannot read calibration file {path}: {exc.strerror or exc}.") from None
    sha = hashlib.sha256(data).hexdigest()
    key = (path, sha)
    if key not in _LOADED:
        try:
            record = json.loads(data.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise TwinInputError(f"Calibration file {path} is not valid JSON: {exc}.") from None
        _LOADED[key] = Calibration(check_record(record, str(path), law=False, data=False), path, sha)
        if _LOADED[key].fast:  # once per file and process
            warnings.warn(f"calibration {_LOADED[key].label()}", FastCalibrationWarning, stacklevel=2)
    if check_table:  # (without: --from reuses the DEM step alone, which its own digest dem.sha256 guards)
        check_data(_LOADED[key].record, str(path))
        if key not in _CONTENT_CHECKED:  # once per file and content: 15 ms of JSON on every twin built
            check_content(_LOADED[key].record, str(path))
            _CONTENT_CHECKED.add(key)
    return _LOADED[key]


def load_calibration(spec=None, check_table: bool = True) -> Calibration:
    """A Calibration from a shipped name (``"dem"``, ``"table"``), a path to a calibration file,
    a Calibration, or a record dict; ``None`` is :data:`DEFAULT_CALIBRATION`. A file or record
    fitted to another reference table than the current one is refused (:func:`check_data`)
    unless ``check_table=False`` (for reusing only its DEM step, ``grindtwin calibrate --from``)."""
    if spec is None:
        spec = DEFAULT_CALIBRATION
    if isinstance(spec, Calibration):
        return spec
    if isinstance(spec, dict):  # a user's record, known by the hash of its content (twin.calibration.model_code)
        # a record in memory is the caller's own study (a file's is checked for edits when read)
        return Calibration(check_record(spec, "the calibration record", data=check_table), None,
                           hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest())
    if isinstance(spec, (str, Path)):
        text = str(spec)
        if text in shipped_names():
            return read_calibration(CALIBRATION_DIR / f"{text}.json", check_table)
        if Path(text).is_file():
            return read_calibration(Path(text), check_table)
        raise TwinInputError(f"The 'calibration' must be a shipped name ({', '.join(shipped_names())}) or the "
                             f"path of a calibration file. Got {text!r}.{close_matches(text, shipped_names())}")
    raise TwinInputError(f"The 'calibration' must be a name, a path, a Calibration or a record dict. Got {spec!r}.")


def shipped_calibration() -> dict:
    """The shipped mineralogy-map calibration's record (``table.json``)."""
    return load_calibration("table").record


def shipped_dem_calibration() -> dict:
    """The shipped DEM-derived calibration's record (``dem.json``)."""
    return load_calibration("dem").record


def lab_mill_values(values: dict) -> dict:
    """The lab mill's fitted fields (twin.mill.Mill) from a fit's ``lab_*`` values."""
    return {k[len("lab_"):]: v for k, v in values.items() if k.startswith("lab_")}


def versions() -> dict:
    """Versions of what shapes a calibration, for its provenance record."""
    from importlib import metadata  # only when a calibration is written: slow to import

    return {"python": platform.python_version(),
            **{pkg: metadata.version(pkg) for pkg in ("numpy", "scipy", "numba", "casadi")}}


def provenance(command: str, **extra) -> dict:
    return {"command": command, **versions(), **extra,
            "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def default_output_path(name: str) -> Path:
    """Where ``grindtwin calibrate`` writes unless told: a new file in the current directory."""
    return Path.cwd() / f"calibration-{name}-{time.strftime('%Y%m%dT%H%M%S')}.json"


#: Commands that wrote calibration files before the file format had its marker (format 1).
_LEGACY_COMMANDS = ("grindtwin calibrate", "python -m twin.calibration")


def _written_by_grindtwin(record) -> bool:
    if not isinstance(record, dict):
        return False
    if record.get("format") == FILE_FORMAT:
        return True
    command = str(record.get("provenance", {}).get("command", ""))
    return command.startswith(_LEGACY_COMMANDS)


def check_writable(path: Path) -> Path:
    """``path`` if a calibration may be written there: a new file, or a calibration file
    grindtwin wrote; TwinInputError before any work otherwise."""
    path = Path(path)
    if path.is_dir():
        raise TwinInputError(f"The calibration output {path} is a folder; give a file path.")
    if path.exists():
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            record = None
        if not _written_by_grindtwin(record):
            raise TwinInputError(f"Refusing to overwrite {path}: it is not a calibration file grindtwin wrote.")
        if record.get("content_sha256") not in (None, *content_digests(record)):  # replaced, with a note only
            raise TwinInputError(f"Refusing to overwrite {path}: it was changed after grindtwin wrote it (its content "
                                 "no longer matches its content_sha256): your edits would be lost. Move it away or "
                                 "give another output file.")
    if not path.parent.is_dir():
        raise TwinInputError(f"The folder of the calibration output {path} does not exist.")
    return path


def write_json_atomically(path: Path, record: dict, indent: int = 2) -> None:
    """Write to a fresh temporary file and rename it over ``path``: nothing is ever half-written,
    and no other file is touched (:mod:`twin.atomic`)."""
    write_text_atomically(path, json_text(record, indent=indent) + "\n")


def write_calibration(path: Path, record: dict) -> Calibration:
    """Check and write a calibration record (refusing what :func:`check_writable` refuses)."""
    record = {**record, "format": FILE_FORMAT, "format_version": FORMAT_VERSION}
    record["content_sha256"] = content_digest(record)
    check_record(record, "the new calibration")
    path = check_writable(path)
    write_json_atomically(path, record, indent=1)
    return read_calibration(path)
