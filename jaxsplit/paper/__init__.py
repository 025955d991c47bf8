"""The audit of the seed paper: every checkable claim re-derived numerically, one module per
section of the paper (``_section2``, ``_section3``, ``_section4``, ``_section4_remarks``); the
registry and runner (``_audit``), verdict rules (``_records``), report.md (``_report``), figures
(``_figures``) and the one function that writes files (``_output.write_audit``)."""

from ._audit import audit_paper as audit_paper
from ._audit import output_names as output_names
from ._audit import run_audit as run_audit
