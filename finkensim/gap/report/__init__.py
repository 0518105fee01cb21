"""Report: the result of a diagnosis (:mod:`.result`, the spec's fields), what it must not claim (:mod:`.honesty`)
and its files, ``report.json``, ``report.md`` and figures (:mod:`.write`)."""
