"""Reports people look at: plots and HTML pages (matplotlib, Agg)."""
