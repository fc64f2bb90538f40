"""The README's report figure: ``cdpr diagnose`` on the shipped EMPS data, one figure of its
report saved as a PNG under ``docs/figures/``.

The EMPS files shipped with the package are converted (``cdpr convert format=emps``) into a
scratch directory and diagnosed there with the command's configuration
(:func:`cdpr_pipeline.diagnose`, black box off: it takes no part in the causes or in this
figure; MLflow logs into the scratch directory). The figure is the report's own
(:func:`cdpr_pipeline.discovery.figures.before_after_figure`): its embedded PNG is
written out byte for byte, so the README shows what ``report.html`` shows. Nothing here
draws a figure of its own, and the PNG is never edited by hand.

    python -m benchmarks.docs_figure                  # docs/figures/emps_before_after.png
    python -m benchmarks.docs_figure --out OTHER.png
"""

from __future__ import annotations

import argparse
import base64
import re
import tempfile
from pathlib import Path

import cdpr_pipeline
from benchmarks.measurements import ROOT
from cdpr_pipeline.data.convert import convert_emps
from cdpr_pipeline.discovery.figures import Figure, before_after_figure
from cdpr_pipeline.resources import emps_path

#: where the README expects the figure
DEFAULT_OUT = ROOT / "docs" / "figures" / "emps_before_after.png"
#: the data URI the report embeds its PNGs as
EMBEDDED_PNG = re.compile(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"')


def png_bytes(figure: Figure) -> bytes:
    """The PNG a report figure embeds."""
    found = EMBEDDED_PNG.search(figure.png)
    if found is None:
        raise ValueError(f"figure {figure.key!r} embeds no PNG")
    return base64.b64decode(found.group(1))


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="the PNG to write")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="cdpr_docs_figure_") as scratch:
        work = Path(scratch)
        data = convert_emps(emps_path(), work / "emps_data")
        diagnosis = cdpr_pipeline.diagnose(
            str(data), "blackbox.enabled=false", out_dir=str(work / "diagnosis"),
            **{"tracking.uri": f"sqlite:///{work / 'mlflow.db'}"})
        figure = before_after_figure(diagnosis)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_bytes(png_bytes(figure))
    print(f"verdict {diagnosis.verdict}; figure {figure.title!r} -> {args.out}")
    return args.out


if __name__ == "__main__":
    main()
