#!/usr/bin/env python3
"""ctest RunGtests.SkippedOnlyWhenNoneRanOrFailed: run_gtests.py on stand-in programs that print
what gtest prints: every test skipped (exit 0) is 77, a failure beside a skip is the failure's
status, passes beside a skip are 0, a crash is a failure."""
import os
import subprocess
import sys

here = os.path.dirname(os.path.abspath(__file__))
cases = [
    # (what the program prints, its exit status, run_gtests.py's expected status)
    ("[  PASSED  ] 0 tests.\n[  SKIPPED ] 3 tests, listed below:\n", 0, 77),
    ("[  PASSED  ] 0 tests.\n[  SKIPPED ] 1 test, listed below:\n[  FAILED  ] 1 test\n", 1, 1),
    ("[  PASSED  ] 2 tests.\n[  SKIPPED ] 1 test, listed below:\n[  FAILED  ] 1 test\n", 1, 1),
    ("[  PASSED  ] 5 tests.\n[  SKIPPED ] 1 test, listed below:\n", 0, 0),
    ("[  PASSED  ] 10 tests.\n", 0, 0),
    ("[ RUN      ] A.B\n", -11, 139),
]
failed = 0
for text, status, want in cases:
    kill = "kill -SEGV $$" if status < 0 else f"exit {status}"
    prog = ["/bin/sh", "-c", f"printf '%s' \"$0\"; {kill}", text]
    got = subprocess.run([sys.executable, os.path.join(here, "run_gtests.py"), *prog],
                         stdout=subprocess.PIPE).returncode
    ok = got == want
    failed += not ok
    print(f"{'ok' if ok else 'FAILED'}: status {status}, {text.splitlines()[0]!r}: "
          f"{got} (want {want})")
sys.exit(1 if failed else 0)
