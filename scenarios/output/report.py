"""A self-contained HTML report of a run directory: KPI table, plots embedded as base64 PNG,
the plant's model beside the controller's, the versions and commit behind the run.

    grindtwin report RUN_DIR      ->  RUN_DIR/report.html

The page needs nothing but itself (no scripts, no external files), so it can be mailed or
archived with the run.
"""

from __future__ import annotations

import base64
import html
import json
import math
import warnings
from pathlib import Path

from scenarios.errors import SceneError
from scenarios.output.labels import (KPI_LABELS, calibration_text, effects_rows, kpi_text, preset_file_text,
                                     replay_rows)
from scenarios.output.plots import PLOTS, plot_caption
from scenarios.output.write import (INCOMPLETE_MARKER, MANIFEST, file_sha256, installed_version,
                                    later_file_is_as_written, lock_folder, lock_path, manifest_files, read_manifest,
                                    record_later_file)
from twin import JSON_INF, release_lock, write_text_atomically

_CSS = """body{font-family:system-ui,sans-serif;max-width:60em;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:.3em .7em;text-align:left}
td.num{text-align:right;font-variant-numeric:tabular-nums}code{font-size:90%}
pre{background:#f6f6f6;padding:.7em;overflow-x:auto;font-size:80%;white-space:pre-wrap}img{max-width:100%}
.na{color:#888}.models{display:grid;grid-template-columns:1fr 1fr;gap:1em}.models h3{margin:.2em 0}
.warnings{border:2px solid #c60;background:#fff4e5;padding:.2em 1em;margin:1em 0}"""


class RunFolderWarning(UserWarning):
    """The run folder a report reads is not as its run left it (files missing or changed, or
    written by another grindtwin version): the report says so at its top."""


def folder_problems(run_dir: Path, summary: dict) -> list[str]:
    """What makes the folder differ from what its run wrote, each as one sentence: files its
    manifest lists that are missing, files whose sha256 differs from the manifest's (edited by
    hand, or copied over), plots its manifest does not list (copied in: the report leaves them
    out, :func:`_plots`), a manifest without checksums (an earlier grindtwin's), and a run
    written by another grindtwin version than the one reporting it."""
    problems = []
    manifest = read_manifest(run_dir)
    if manifest is None:
        problems.append(f"no {MANIFEST} written by grindtwin here: nothing can be checked against what the "
                        "run wrote")
    else:
        listed = [str(f) for f in manifest["files"]]
        missing = [f for f in listed if not (run_dir / f).is_file()]
        if missing:
            problems.append(f"files the run wrote are missing: {', '.join(missing)}; the report shows what "
                            "is left")
        sums = manifest.get("sha256")
        if isinstance(sums, dict):
            changed = [f for f in listed if f not in missing and sums.get(f) != file_sha256(run_dir / f)]
            if changed:
                problems.append(f"changed since the run wrote them (their sha256 differs from {MANIFEST}'s): "
                                f"{', '.join(changed)}; what the report shows from them may not be the run's")
        else:
            problems.append(f"{MANIFEST} records no checksums (an earlier grindtwin wrote it): its files cannot "
                            "be checked against what the run wrote")
        unlisted = [f for f in PLOTS if (run_dir / f).is_file() and f not in listed]
        if unlisted:
            problems.append(f"plots the run did not write are in its folder (copied in?): {', '.join(unlisted)}; "
                            "the report leaves them out")
    versions = summary.get("versions")
    ran = (versions.get("grindtwin") if isinstance(versions, dict) else None) or (manifest or {}).get(
        "grindtwin_version")
    here = installed_version()
    if ran and here and ran != here:
        problems.append(f"the run was written by grindtwin {ran} and this report by {here}: KPI names and "
                        "definitions are those of the run's version")
    return problems


def _fmt(key: str, value) -> str:
    if value in JSON_INF.values():  # summary.json's infinity: a value, not n/a
        value = float(value)
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return '<span class="na">n/a</span>'
    try:
        return html.escape(kpi_text(key, value))
    except (ValueError, TypeError):
        return html.escape(str(value))


def kpi_table(kpis: dict) -> str:
    """The KPIs as an HTML table (key, meaning, value); n/a for undefined ones."""
    rows = []
    for key, value in kpis.items():
        label = KPI_LABELS.get(key, (key, ""))[0]
        rows.append(f"<tr><td><code>{html.escape(key)}</code></td><td>{html.escape(label)}</td>"
                    f'<td class="num">{_fmt(key, value)}</td></tr>')
    return ('<table class="kpis"><thead><tr><th>KPI</th><th>meaning</th><th>value</th></tr></thead>'
            "<tbody>" + "".join(rows) + "</tbody></table>")


def _img(path: Path, caption: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def models_section(summary: dict) -> str:
    """The plant's model (what was simulated) beside the controller's (None open loop)."""
    plant = summary.get("plant_model") or ""
    ctl = summary.get("controller_model") or "none: open loop, the scene's inputs"
    cols = [("Plant (simulated)", plant), ("Controller's model", ctl)]
    return ('<h2>Models</h2><div class="models">' + "".join(
        f"<div><h3>{html.escape(title)}</h3><pre>{html.escape(text)}</pre></div>" for title, text in cols)
        + "</div>")


def versions_section(versions: dict) -> str:
    """The versions behind the run; the git commit, or why there is none."""
    code = {k: versions.get(k) for k in ("git", "git_source")}
    libs = ", ".join(f"{html.escape(k)} {html.escape(str(v))}" for k, v in versions.items() if k not in code)
    commit = (f"git commit <code>{html.escape(str(code['git']))}</code>" if code["git"]
              else "no git commit")
    source = f" ({html.escape(str(code['git_source']))})" if code["git_source"] else ""
    return f"<h2>Versions</h2><p>{libs}</p><p>{commit}{source}</p>"


def _run_summary(run_dir: Path) -> dict:
    """The summary of a complete run folder; SceneError for anything else."""
    if run_dir.is_file():
        raise SceneError(f"{run_dir}: a file, not a run directory (give the folder it is in: {run_dir.parent})")
    if not run_dir.is_dir():
        raise SceneError(f"{run_dir}: run directory not found")
    if (run_dir / INCOMPLETE_MARKER).exists():
        raise SceneError(f"{run_dir}: the run is incomplete ({INCOMPLETE_MARKER} present)")
    summary_path = run_dir / "summary.json"
    if not summary_path.is_file():
        kind = (read_manifest(run_dir) or {}).get("kind")
        what = (f"a grindtwin {kind} folder, not a run's" if kind and kind != "run"
                else "not a grindtwin run directory")
        raise SceneError(f"{run_dir}: no summary.json; {what} (write one with: grindtwin run SCENE --out DIR)")
    return read_summary(summary_path)


def render_report(run_dir) -> str:
    """The HTML text of the report of ``run_dir`` (SceneError if it is not a complete run); what
    makes the folder differ from what its run wrote opens the page (:func:`folder_problems`)."""
    run_dir = Path(run_dir)
    summary = _run_summary(run_dir)
    return _render(run_dir, summary, folder_problems(run_dir, summary))


#: Fields of summary.json the report reads -> their JSON type (a hand-edited one raised a traceback).
SUMMARY_FIELDS = {"replay": dict, "versions": dict, "calibration": dict, "mill_preset_file": dict,
                  "history_file": dict, "psd_file": dict, "effects": list, "plant_effects": list, "components": list,
                  "notes": list, "warnings": list, "description": str}
_JSON_NAMES = {dict: "object", list: "array", str: "string"}


def read_summary(path: Path) -> dict:
    """A run's summary.json; SceneError naming the file and the field when it is not a run's
    summary (an object with a ``kpis`` object)."""
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise SceneError(f"{path}: not valid JSON: {exc}") from None
    if not isinstance(summary, dict):
        raise SceneError(f"{path}: a run's summary is a JSON object, got a {type(summary).__name__}")
    if not isinstance(summary.get("kpis"), dict):
        raise SceneError(f"{path}: 'kpis' must be an object of KPI name -> number, got {summary.get('kpis')!r}")
    for key, kind in SUMMARY_FIELDS.items():  # the fields the report reads, when present
        value = summary.get(key)
        if value is not None and not isinstance(value, kind):
            raise SceneError(f"{path}: '{key}' must be a JSON {_JSON_NAMES[kind]}, got {value!r}")
    if summary.get("replay") and not isinstance(summary["replay"].get("run_minus_recorded", {}), dict):
        raise SceneError(f"{path}: 'replay.run_minus_recorded' must be a JSON object, got "
                         f"{summary['replay']['run_minus_recorded']!r}")
    return summary


def _render(run_dir: Path, summary: dict, problems: list[str]) -> str:
    name = html.escape(str(summary.get("scene", run_dir.name)))
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>grindtwin: {name}</title>"
             f"<style>{_CSS}</style></head><body>",
             f"<h1>{name}</h1>"]
    if summary.get("description"):
        parts.append(f"<p>{html.escape(summary['description'])}</p>")
    facts = [("mode", summary.get("mode")), ("controller", summary.get("controller")),
             ("target P80 [µm]", summary.get("target_p80_um")), ("seed", summary.get("seed")),
             *effects_rows(summary),
             ("components", ", ".join(map(str, summary.get("components", [])))),
             ("calibration", calibration_text(summary.get("calibration"))),
             ("mill preset file", preset_file_text(summary.get("mill_preset_file"))),
             ("scene file", summary.get("source")), *replay_rows(summary),
             ("history file", preset_file_text(summary.get("history_file"))),
             ("feed screen analysis file", preset_file_text(summary.get("psd_file")))]
    parts.append("<table>" + "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>"
                                     for k, v in facts if v is not None) + "</table>")
    run_warnings = [str(w) for w in summary.get("warnings") or []]
    shown = problems + run_warnings  # the folder's problems first: they qualify everything below
    if shown:  # before the numbers they qualify, not among the notes at the end
        parts.append('<div class="warnings"><h2>Warnings</h2><ul>'
                     + "".join(f"<li>{html.escape(w)}</li>" for w in shown) + "</ul></div>")
    parts.append("<h2>Key performance indicators</h2>")
    parts.append(kpi_table(summary.get("kpis", {})))
    if summary.get("replay"):
        parts.append("<h2>Replay: run minus recorded</h2>")
        parts.append(kpi_table(summary["replay"].get("run_minus_recorded", {})))
    parts.append("<h2>Plots</h2>")
    plots = _plots(run_dir)
    for fname in plots:
        parts.append(_img(run_dir / fname, plot_caption(fname, summary)))
    if not plots:
        parts.append("<p>None in the run folder (a run written with --no-plots has none).</p>")
    notes = [str(n) for n in summary.get("notes") or [] if str(n) not in run_warnings]
    if notes:
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in notes) + "</ul>")
    parts.append(models_section(summary))
    if summary.get("versions"):
        parts.append(versions_section(summary["versions"]))
    parts.append("</body></html>")
    return "\n".join(parts)


def _plots(run_dir: Path) -> list[str]:
    """The plots of :data:`PLOTS` in the folder that its run wrote: those its manifest lists (a p80.png copied
    from another run into a folder written with --no-plots was shown as this run's); every one there when the
    folder has no manifest (:func:`folder_problems` says nothing can be checked)."""
    listed = manifest_files(run_dir)
    return [f for f in PLOTS if (run_dir / f).is_file() and (listed is None or f in listed)]


def write_report(run_dir) -> Path:
    """Write ``run_dir/report.html`` (via a temporary file, renamed when complete), only into a
    folder grindtwin wrote (its manifest lists summary.json): a ``report.html`` of the user's
    beside a ``summary.json`` of their own is never replaced. The report's sha256 is recorded in
    the manifest (``later_sha256``); a ``report.html`` whose content is not what grindtwin last
    wrote there (edited by hand, a file of the user's) is refused, not replaced, unless it holds
    the very page about to be written. What makes the folder differ from what its run wrote opens
    the page and is warned of (:class:`RunFolderWarning`). It holds the folder's ``DIR.lock``
    throughout, as ``grindtwin run --out DIR`` does (:func:`scenarios.output.write.lock_folder`): a
    run replacing the folder meanwhile put the page of the old run into the new run's folder."""
    run_dir = Path(run_dir)
    _run_summary(run_dir)  # a folder that is no run's is refused before a lock is made beside it
    try:
        fd = lock_folder(run_dir, lambda why: SceneError(f"{run_dir}: {why}; no report was written"))
    except OSError as exc:
        raise SceneError(f"{run_dir}: cannot make its lock {lock_path(run_dir).name} beside it "
                         f"({exc.strerror or exc}); no report was written") from None
    try:
        return _write_locked(run_dir)
    finally:
        release_lock(lock_path(run_dir), fd)


def _write_locked(run_dir: Path) -> Path:
    """:func:`write_report`'s work, under the folder's lock."""
    summary = _run_summary(run_dir)
    if "summary.json" not in (manifest_files(run_dir) or []):
        raise SceneError(f"{run_dir}: summary.json is not listed in a {MANIFEST} written by grindtwin; the report "
                         "is written only into a run folder grindtwin made (grindtwin run SCENE --out DIR), "
                         "so nothing of yours there is replaced")
    problems = folder_problems(run_dir, summary)
    text = _render(run_dir, summary, problems)
    for problem in problems:  # on stderr too, not only inside the page
        warnings.warn(f"{run_dir}: {problem}", RunFolderWarning, stacklevel=3)
    out = run_dir / "report.html"
    if (out.is_symlink() or out.is_file()) and not (later_file_is_as_written(run_dir, out.name)
                                                   or _holds(out, text)):
        raise SceneError(f"{out}: this report.html is not the one grindtwin last wrote here (edited since, a file of "
                         "yours, or written by a grindtwin that kept no record of it), so it was left as it is "
                         "and no report was written. Move it out of the folder (or delete it if you do not need "
                         f"it), then run again: grindtwin report {run_dir}")
    # via a temporary file no one else holds: a full disk, a report.html that is a folder, Ctrl-C leave
    # no half-written page, and a report.html.partial of the user's is not taken
    write_text_atomically(out, text)
    sha256 = file_sha256(out)
    record_later_file(run_dir, out.name, sha256)  # killed before this: the page is refused next time, not lost
    return out


def _holds(path: Path, text: str) -> bool:
    """Whether the regular file ``path`` holds exactly ``text`` (replacing it loses nothing)."""
    try:
        return not path.is_symlink() and path.read_text(encoding="utf-8") == text
    except (OSError, UnicodeDecodeError):
        return False
