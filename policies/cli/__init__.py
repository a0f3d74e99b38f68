"""The learning side's commands (``hrlsac train``, ``sweep``, ``evaluate``, ``compare``, ``export``): argument
parsing and output only; the work is in the sibling packages."""
