"""What a user looks at: validation figures (PNG, matplotlib Agg), the HTML report page, where a result came from
(provenance), and the MATLAB-``compare``-like comparison of saved models on new data.

matplotlib is imported when the first figure is drawn.
May import: :mod:`sysid.errors`, :mod:`sysid.data`, :mod:`sysid.evaluation`, :mod:`sysid.registry` (by name).
"""

from typing import TYPE_CHECKING

from sysid._exports import attach

if TYPE_CHECKING:
    from sysid.report.compare import compare_report, horizon_label, parse_horizon, predict_scores
    from sysid.report.html import REPORT_CSS, esc, figure, image, page, provenance_section, table, write_page
    from sysid.report.linplots import linear_report, plot_bode_with_std, plot_simulation_band
    from sysid.report.plots import (
        identification_report,
        plot_bla,
        plot_compare,
        plot_correlation_tests,
        plot_frf,
        plot_horizon_residuals,
        plot_measured_vs_predicted,
        plot_residuals,
        plot_scatter,
    )
    from sysid.report.provenance import file_sha256, html_block

__getattr__, __dir__, __all__ = attach(__name__, __file__)
