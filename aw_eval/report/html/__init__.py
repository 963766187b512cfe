"""``report.html``: the report as one page that opens offline, with a card per task (pictures of
every system's final state beside the target, filmstrips, curves, tool calls) and a 3D view.

Assets, pictures and the 3D view's data go into the sibling folder ``report_files/``."""

from aw_eval.report.html.page import ASSETS_DIR, write_html

__all__ = ["write_html", "ASSETS_DIR"]
