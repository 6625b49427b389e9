import os
import sys

from pipeline.cli import main

try:
    code = main()
    sys.stdout.flush()
except BrokenPipeError:
    # The reader went away (`python -m pipeline claims | head`): no traceback; Python's own
    # exit code for it. stdout goes to devnull so the flush at exit cannot raise again.
    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    code = 1
sys.exit(code)
