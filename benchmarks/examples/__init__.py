"""Models written as a user would write them (``diagnose --model``), with the runs that diagnose them on the
benchmark library's measured records."""
