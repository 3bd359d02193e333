"""The report directory of ``doorbatch evaluate``: metrics.parquet, report.md, report.html and PNG plots.

``write_report(evaluation, out_dir) -> list[Path]`` writes, atomically each:

* ``metrics.parquet``: one row per metric (DESIGN schema: run, log, method, metric, value, unit, params JSON);
* the plots (matplotlib, Agg backend), those that have data: ``error_along_x.png`` (position error along the
  corridor per method, mean ± std over runs: paper 000 Figs. 5–7), ``error_over_time.png``,
  ``door_state_error.png``, ``global_success.png`` (success rate against particles: Figs. 8–9);
* ``report.md`` (the tables, the plots linked) and ``report.html`` (self-contained: the PNGs embedded as
  base64 data URIs, so the one file opens anywhere).
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from doorbatch.io.atomic import atomic_write_bytes, atomic_write_text
from doorbatch.io.parquet import write_table
from doorbatch.pipeline.evaluate.report import (
    DOORPOSE_METRICS,
    MAP_METRICS,
    Evaluation,
    SummaryTable,
    metric_columns,
    summary_table,
)

Plot = tuple[str, str, bytes]  # file name, caption, PNG bytes
_COLORS = {"mcl": "tab:red", "rbpf": "tab:blue"}


def _figure(draw: Callable[[Any], None], n_panels: int = 1, height: float = 3.2) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(n_panels, 1, figsize=(7.5, height * n_panels), squeeze=False)
    draw(axes[:, 0])
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return buf.getvalue()


def _along_x_plot(evaluation: Evaluation) -> Plot | None:
    curves = evaluation.along_corridor
    if not curves:
        return None
    logs = sorted({c.log for c in curves})

    def draw(axes: Any) -> None:
        for ax, log_name in zip(axes, logs, strict=True):
            for c in (c for c in curves if c.log == log_name):
                color = _COLORS.get(c.method)
                ax.plot(c.x_m, c.mean_error_m, label=f"{c.method} ({c.runs} runs)", color=color,
                        linestyle="-" if c.method == "mcl" else "--")
                ax.fill_between(c.x_m, c.mean_error_m - c.std_error_m, c.mean_error_m + c.std_error_m,
                                color=color, alpha=0.15)
            ax.set_title(log_name)
            ax.set_xlabel("x along the corridor (m)")
            ax.set_ylabel("position error (m)")
            ax.set_ylim(bottom=0.0)
            ax.grid(alpha=0.3)
            ax.legend()

    return ("error_along_x.png", "Localization error along the corridor (mean ± std over runs; paper 000 "
            "Figs. 5–7)", _figure(draw, len(logs)))


def _over_time_plot(evaluation: Evaluation) -> Plot | None:
    series = evaluation.errors
    if not series:
        return None
    logs = sorted({s.log for s in series})

    def draw(axes: Any) -> None:
        for ax, log_name in zip(axes, logs, strict=True):
            labelled: set[str] = set()
            for s in (s for s in series if s.log == log_name):
                ax.plot(s.t_s, s.position_error_m, color=_COLORS.get(s.method), alpha=0.6, linewidth=0.8,
                        label=None if s.method in labelled else s.method)
                labelled.add(s.method)
            ax.set_title(log_name)
            ax.set_xlabel("time (s)")
            ax.set_ylabel("position error (m)")
            ax.set_ylim(bottom=0.0)
            ax.grid(alpha=0.3)
            ax.legend()

    return "error_over_time.png", "Localization error over time (every run)", _figure(draw, len(logs))


def _door_state_plot(evaluation: Evaluation) -> Plot | None:
    series = evaluation.door_states
    if not series:
        return None

    def draw(axes: Any) -> None:
        ax = axes[0]
        for s in series:
            ax.plot(s.t_s, np.degrees(s.error_rad), linewidth=0.8, alpha=0.7, label=s.run)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("door angle error (deg)")
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
        if len(series) <= 8:
            ax.legend()

    return ("door_state_error.png", "Door-state error over time (mean over doors observed in the window)",
            _figure(draw))


def _success_plot(evaluation: Evaluation) -> Plot | None:
    curves = evaluation.success
    if not curves:
        return None

    def draw(axes: Any) -> None:
        ax = axes[0]
        markers = {name: "osD^v<>"[k % 7] for k, name in enumerate(sorted({c.log for c in curves}))}
        for c in curves:
            ax.semilogx(c.particles, 100 * c.success_rate, marker=markers[c.log], color=_COLORS.get(c.method),
                        linestyle="-" if c.method == "rbpf" else "--", label=f"{c.method}, {c.log}")
        ax.set_xlabel("particles")
        ax.set_ylabel("success rate (%)")
        ax.set_ylim(-5, 105)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()

    return ("global_success.png", "Global localization success rate against the particle count (paper 000 "
            "Figs. 8–9)", _figure(draw))


def _format(value: float, unit: str) -> str:
    if not math.isfinite(value):
        return "–"
    if unit == "bool":
        return f"{100 * value:.0f} %"
    return f"{value:.3f}" if abs(value) < 100 else f"{value:.1f}"


def table_lines(table: SummaryTable) -> list[str]:
    """A Markdown table."""
    head = [*table.label_columns, *(f"{c} ({u})" for c, u in zip(table.value_columns, table.units, strict=True))]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for labels, values in table.rows:
        cells = [*labels, *(_format(v, u) for v, u in zip(values, table.units, strict=True))]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _tables(evaluation: Evaluation) -> list[tuple[str, SummaryTable]]:
    out = [("Localization runs (mean over seeds)", summary_table(evaluation)),
           ("Door maps", summary_table(evaluation, MAP_METRICS, method_map=True)),
           ("Door poses (paper 003)", summary_table(evaluation, DOORPOSE_METRICS))]
    return [(title, t) for title, t in out if t.rows]


LEFT_OUT = ("These steps failed, or were blocked by one that failed: the report has no rows of them. Their errors "
            "are in the batch's summary.json and run.log.")


def render_markdown(evaluation: Evaluation, plots: list[Plot]) -> str:
    """report.md: title, tables, plots as image links."""
    parts = [f"# {evaluation.title}", ""]
    if evaluation.left_out:
        parts += ["## Left out", "", LEFT_OUT, "", *(f"- `{step}`" for step in evaluation.left_out), ""]
    for title, table in _tables(evaluation):
        parts += [f"## {title}", "", *table_lines(table), ""]
    for name, caption, _ in plots:
        parts += [f"![{caption}]({name})", "", f"*{caption}*", ""]
    parts += ["All metrics (one row each) are in `metrics.parquet`.", ""]
    return "\n".join(parts)


def render_html(evaluation: Evaluation, plots: list[Plot]) -> str:
    """report.html: the same content, self-contained (plots as data URIs)."""
    body = [f"<h1>{html.escape(evaluation.title)}</h1>"]
    if evaluation.left_out:
        body.append(f"<h2>Left out</h2><p>{html.escape(LEFT_OUT)}</p><ul>"
                    + "".join(f"<li><code>{html.escape(step)}</code></li>" for step in evaluation.left_out) + "</ul>")
    for title, table in _tables(evaluation):
        body.append(f"<h2>{html.escape(title)}</h2><table>")
        head = [*table.label_columns, *(f"{c} ({u})" for c, u in zip(table.value_columns, table.units, strict=True))]
        body.append("<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>")
        for labels, values in table.rows:
            cells = [*labels, *(_format(v, u) for v, u in zip(values, table.units, strict=True))]
            body.append("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
        body.append("</table>")
    for _, caption, png in plots:
        data = base64.b64encode(png).decode("ascii")
        body.append(f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
                    f"<figcaption>{html.escape(caption)}</figcaption></figure>")
    style = ("body{font-family:sans-serif;margin:2em;max-width:80em}table{border-collapse:collapse}"
             "td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}img{max-width:100%}")
    return (f"<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{html.escape(evaluation.title)}</title>"
            f"<style>{style}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n")


def render_plots(evaluation: Evaluation) -> list[Plot]:
    """Every plot that has data."""
    made = [p(evaluation) for p in (_along_x_plot, _over_time_plot, _door_state_plot, _success_plot)]
    return [p for p in made if p is not None]


def write_report(evaluation: Evaluation, out_dir: Path) -> list[Path]:
    """Write metrics.parquet, the PNG plots, report.md and report.html into ``out_dir``; returns their paths.

    Raises:
        OSError: a file cannot be written.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    write_table("metrics", metric_columns(evaluation.metrics), out_dir / "metrics.parquet")
    plots = render_plots(evaluation)
    for name, _, png in plots:
        atomic_write_bytes(out_dir / name, png)
    atomic_write_text(out_dir / "report.md", render_markdown(evaluation, plots))
    atomic_write_text(out_dir / "report.html", render_html(evaluation, plots))
    return [out_dir / "metrics.parquet", *(out_dir / n for n, _, _ in plots), out_dir / "report.md",
            out_dir / "report.html"]


def stdout_table(evaluation: Evaluation) -> str:
    """The short table ``doorbatch evaluate`` prints: the localization and map tables in Markdown."""
    lines: list[str] = []
    for title, table in _tables(evaluation):
        lines += [title + ":", *table_lines(table), ""]
    return "\n".join(lines).rstrip()

