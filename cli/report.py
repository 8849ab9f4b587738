"""The batch's reports: the progress bar (stderr), the summary table and
line (stdout), the JSON report.

The table has one row per file whatever its texts hold: newlines and pipes
in a name or an error are escaped, so a row is always one line of 8 cells.
"""

import json
import math
import os
import sys
from collections import Counter

from ..core.metrics import percent


def progress_bar(done, total, name, width=28):
    filled = int(width * done / max(total, 1))
    sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} {name[:40]:<40}")
    if done == total:
        sys.stderr.write("\n")
    sys.stderr.flush()


def _cell(text):
    """Text safe in one Markdown table cell: one line, pipes escaped."""
    text = str(text).replace("|", "\\|")
    return text.replace("\r\n", "\\n").replace("\n", "\\n").replace("\r", "\\n").strip()


def _status(r):
    s = r["status"]
    if s == "ok":
        return "ok"
    if s == "warn":
        return "warn: " + "; ".join(r["warnings"])
    if s == "failed":
        return "FAILED: " + (r.get("error") or "unknown")
    if s == "skipped":
        return "skipped: outputs exist"
    return s


def summary_table(results):
    """The Markdown table of the batch's files, a row each (the deviation as
    the add-on says it: ``core.percent``, two significant digits below 0.1%)."""
    lines = ["| file | faces in | cage faces | target | max deviation | refined faces | time s "
             "| status |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]

    def num(v, fmt="{:,}"):
        return "" if v is None else fmt.format(v)

    for r in results:
        dev = r.get("deviation_pct")
        lines.append("| " + " | ".join(_cell(c) for c in (
            r["name"], num(r.get("faces_in")), num(r.get("faces_out")),
            num(r.get("target_faces")), "" if dev is None else percent(dev / 100.0),
            num(r.get("refined_faces")), num(r.get("seconds"), "{:.2f}"), _status(r))) + " |")
    return "\n".join(lines)


def counts(results):
    c = Counter(r["status"] for r in results)
    return {k: c.get(k, 0) for k in ("ok", "warn", "failed", "skipped", "cancelled")}


def summary_line(results, out):
    c = counts(results)
    line = f"{c['ok'] + c['warn']} converted"
    if c["warn"]:
        line += f" ({c['warn']} with warnings)"
    line += f", {c['failed']} failed"
    for k in ("skipped", "cancelled"):
        if c[k]:
            line += f", {c[k]} {k}"
    return line + f"; output in {out}"


def write_json(path, data):
    """Write ``data`` as JSON to ``path`` through a short temporary name in its
    folder (any name the folder takes does), then rename."""
    tmp = os.path.join(os.path.dirname(path), f".report.part-{os.getpid()}")
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(data, fh, indent=1, allow_nan=False, default=str)
        fh.write("\n")
    os.replace(tmp, path)


def json_safe(r):
    """NaN and infinity are not JSON: None instead."""
    return {k: None if isinstance(v, float) and not math.isfinite(v) else v for k, v in r.items()}
