#!/usr/bin/env python3
"""Runs test_shim_failures under QEMU: expects exit status 5 (five failed
tests), one pass, one skip, and each failure's message.

    shim_harness.py QEMU_RUN IMAGE
"""
import subprocess
import sys

EXPECTED = [
    "[       OK ] test_passes",
    "1 (0x1) != 2 (0x2)",
    "[  FAILED  ] test_int_equal_fails",
    "18446744073709551615 is not within range [0, 10]",
    "[  FAILED  ] test_negative_is_out_of_unsigned_range",
    "memory differs at byte 2: 0x63 != 0x78 of 4 bytes",
    "golden sample 42 differs by 0.5",
    "[  SKIPPED ] test_skips",
    "[  ERROR   ] fixture returned an error",
    "[  FAILED  ] test_not_run_after_failed_setup",
    "[  PASSED  ] 1 test(s).",
    "[  FAILED  ] shim: 5 test(s), listed below:",
]


def main(qemu_run, image):
    run = subprocess.run([qemu_run, image], capture_output=True, text=True)
    print(run.stdout)
    missing = [e for e in EXPECTED if e not in run.stdout]
    ok = run.returncode == 5 and not missing and "not reached" not in run.stdout
    if not ok:
        print(f"shim_harness: exit status {run.returncode} (want 5); missing: {missing}")
        return 1
    print("shim_harness: failures, skip and fixture error reported, exit status 5")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
