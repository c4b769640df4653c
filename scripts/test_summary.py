#!/usr/bin/env python3
"""Counts the test cases in catkin's JUnit result files (gtest, rostest, pytest) and prints
every skipped test with its reason (e.g. a clone without ../shared/data), every failed one, and
one closing line 'rover tests: N passed, M failed, K skipped'. Exit status 1 if any test
failed or errored, or if no test ran at all. (catkin_test_results counts gtest's nested
<testsuites> twice, so it is not used for the numbers.)"""
import glob
import os
import sys
import xml.etree.ElementTree as ET


def main(results_dir):
    passed = failed = skipped = 0
    failures = []
    skips = []
    for path in sorted(glob.glob(os.path.join(results_dir, "**", "*.xml"), recursive=True)):
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError as e:
            failed += 1
            failures.append(f"{path}: unreadable result file ({e})")
            continue
        for case in root.iter("testcase"):
            name = f"{case.get('classname', '')}.{case.get('name', '')}"
            if case.find("failure") is not None or case.find("error") is not None:
                failed += 1
                failures.append(f"{os.path.basename(path)}: {name}")
            elif case.find("skipped") is not None or case.get("status") == "notrun":
                skipped += 1
                why = case.find("skipped")
                why = " ".join(((why.get("message") or why.text or "") if why is not None else "not run").split())
                skips.append(f"{os.path.basename(path)}: {name}: {why}")
            else:
                passed += 1
    for s in skips:
        print(f"SKIPPED {s}")
    for f in failures:
        print(f"FAILED {f}")
    print(f"rover tests: {passed} passed, {failed} failed, {skipped} skipped")
    return 1 if failed or passed == 0 else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
