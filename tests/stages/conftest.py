"""The end-to-end tests record each `cdpr repro`'s wall time as a ``repro_s NAME`` user
property; this prints them after the run, also under pytest-xdist (whose workers' own
output is not shown)."""

from __future__ import annotations


def pytest_terminal_summary(terminalreporter) -> None:
    seconds: dict[str, object] = {}
    for reports in terminalreporter.stats.values():
        for report in reports:
            for key, value in getattr(report, "user_properties", None) or ():
                if isinstance(key, str) and key.startswith("repro_s "):
                    seconds[key.removeprefix("repro_s ")] = value
    if seconds:
        terminalreporter.write_sep("-", "cdpr repro wall time")
        for name, value in seconds.items():
            terminalreporter.write_line(f"{name}: {value} s")
