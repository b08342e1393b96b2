"""What the rules (``loop_rules.py``) use of Cython's shadow module when they run as Python and Cython is not
installed (it is needed only to generate ``_loop_rules.c``: requirements-dev.txt): they ask only whether
they are compiled. Their annotations (``cython.double``...) are never evaluated as Python."""
compiled = False
