"""The paper's three results tables, one command each (``wbc paper table1|table2|table3``): protocols, numbers, text."""

from wbc.tools.paper.format import format_paper_table, verdict
from wbc.tools.paper.paper_numbers import (
    PROTOCOL_I,
    PROTOCOL_II,
    PROTOCOL_III,
    TABLE_I,
    TABLE_II,
    TABLE_III,
    PaperProtocol,
    PaperValue,
)
from wbc.tools.paper.paper_table import (
    DEFAULT_SEEDS,
    DEFAULT_TRIALS,
    PaperRunConfig,
    PaperTableResult,
    default_out_dir,
    run_paper_table,
)
from wbc.tools.paper.tables import TABLES, Contender, Contrast, PaperTableSpec, resolve_contenders

__all__ = ["DEFAULT_SEEDS", "DEFAULT_TRIALS", "PROTOCOL_I", "PROTOCOL_II", "PROTOCOL_III", "TABLES", "TABLE_I",
           "TABLE_II", "TABLE_III", "Contender", "Contrast", "PaperProtocol", "PaperRunConfig", "PaperTableResult",
           "PaperTableSpec", "PaperValue", "default_out_dir",
           "format_paper_table", "resolve_contenders", "run_paper_table", "verdict"]
