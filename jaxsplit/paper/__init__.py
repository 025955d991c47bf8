"""The audit of the seed paper: every checkable claim re-derived numerically (``_audit``),
with its report and figures (``_figures``)."""

from ._audit import audit_paper as audit_paper
