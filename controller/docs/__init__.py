"""Reference pages generated from the code (``finepos docs``): the configuration reference from
the typed config dataclasses, the results page from ``finepos evaluate`` reports."""
