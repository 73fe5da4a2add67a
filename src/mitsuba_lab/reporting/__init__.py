"""Report helpers shared by the sweep report, ``mitsuba-lab invert`` and ``mitsuba-lab check``.

* ``numbers``: number formatting for table cells (``fmt``);
* ``tables``: Markdown tables and CSV files;
* ``page``: Markdown -> self-contained HTML (images embedded), page writing;
* ``figures``: matplotlib on a headless backend, atomic PNG writing, log-log plots.

Every file is written through ``mitsuba_lab.images.atomic_path``: to a temporary name,
then renamed, with the mode the umask gives.
"""
from .figures import pyplot, save_figure, save_loglog
from .numbers import fmt, fmt_column, fmt_pm, fmt_pm_column, separating_digits
from .page import block_marker, embedded_image, html_page, html_table, md_to_html, write_markdown_page, write_text
from .tables import dict_rows, markdown_table, write_csv

__all__ = ["fmt", "fmt_column", "fmt_pm", "fmt_pm_column", "separating_digits", "markdown_table", "write_csv", "dict_rows", "md_to_html", "html_table", "html_page",
           "embedded_image", "block_marker", "write_text", "write_markdown_page", "pyplot", "save_figure", "save_loglog"]
