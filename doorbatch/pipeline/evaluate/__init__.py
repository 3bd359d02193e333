"""Metrics against a reference: trajectories (as evo), localization, door maps and door states; reports.

The public API: :func:`~doorbatch.pipeline.evaluate.report.evaluate_runs` (pure),
:func:`~doorbatch.pipeline.evaluate.stage.evaluate_run_dirs` (reads runs, writes the report directory) and
:func:`doorbatch.io.report_writer.write_report`.
"""
