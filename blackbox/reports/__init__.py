"""Reports, separate from results (lmfit's ``fit_report``): Markdown text and PNG plots, one
module per command. A command's typed result calls its report module from ``write(out)``."""
