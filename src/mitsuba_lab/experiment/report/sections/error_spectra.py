"""The radially averaged power spectrum of each strategy's error (``spectrum``)."""
from __future__ import annotations

import os

from ..analysis import run_image
from ..spectrum import plot_error_spectra


def applies(view) -> bool:
    return bool(view.groups)


def render(view) -> list[str]:
    report = view.report
    spectra = plot_error_spectra(view.groups, view.label, view.ref.image, report.folder,
                                 os.path.join(report.out, f"{view.scene}_spectra.png"),
                                 read_image=lambda p: run_image(report.folder, os.path.relpath(p, report.folder)))
    if not spectra:
        return []
    return ["", f"![radially averaged power spectrum of the error]({os.path.basename(spectra)})"]
