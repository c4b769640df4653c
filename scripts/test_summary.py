#!/usr/bin/env python3
"""Counts the test cases in catkin's JUnit result files (gtest, rostest, pytest) and prints
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
            else:
                passed += 1
    for f in failures:
        print(f"FAILED {f}")
    print(f"rover tests: {passed} passed, {failed} failed, {skipped} skipped")
    return 1 if failed or passed == 0 else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
