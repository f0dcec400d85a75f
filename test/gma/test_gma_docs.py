"""docs/apply_gma.md runs as printed: its Python blocks, run in order as one file in a temporary directory, print
exactly the page's "Output" blocks (every noise in the example is seeded, so the text is exact).

The page is run once, in a subprocess (the example writes ``cstr_rto.sqlite`` into its working directory and
resumes from it); about 12 s, most of it the noisy-plant comparison over five seeds.
"""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "apply_gma.md"
SECTIONS = ("Part 1", "Part 2", "A noisy plant")


def blocks():
    """``[(code, output), ...]`` in page order: each ```python block and the ``` block after the next line that
    starts with "Output"."""
    text = PAGE.read_text(encoding="utf-8")
    fence = re.compile(r"^```(\w*)\n(.*?)^```$", re.M | re.S)
    found = [(m.start(), m.group(1), m.group(2)) for m in fence.finditer(text)]
    pairs, code = [], None
    for start, lang, body in found:
        if lang == "python":
            assert code is None, "two Python blocks without an Output block between them"
            code = body
        elif lang == "" and code is not None:
            last_line = text[:start].rstrip().rsplit("\n", 1)[-1]
            assert last_line.startswith("Output"), f"the block after {last_line!r} is not an Output block"
            pairs.append((code, body))
            code = None
    assert code is None, "a Python block without its Output block"
    return pairs


@pytest.fixture(scope="module")
def page_run(tmp_path_factory):
    """Runs the page's code as one file; returns (stdout, stderr, returncode, working directory)."""
    cwd = tmp_path_factory.mktemp("apply_gma")
    script = cwd / "cstr_gma.py"
    script.write_text("\n\n".join(code for code, _ in blocks()), encoding="utf-8")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    proc = subprocess.run([sys.executable, str(script)], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)
    return proc.stdout, proc.stderr, proc.returncode, cwd


def test_the_page_has_the_three_parts_each_with_its_output():
    pairs = blocks()
    assert len(pairs) == len(SECTIONS)
    assert all(out.strip() for _, out in pairs)


def test_the_page_runs(page_run):
    stdout, stderr, code, cwd = page_run
    assert code == 0, f"the page's code failed:\n{stderr[-3000:]}"
    assert (cwd / "cstr_rto.sqlite").exists()          # Part 2's resumable history, in the temporary directory


@pytest.mark.parametrize("part", range(len(SECTIONS)), ids=SECTIONS)
def test_each_part_prints_its_output_block(page_run, part):
    stdout, stderr, code, _ = page_run
    outputs = [out for _, out in blocks()]
    before = "".join(outputs[:part])
    assert stdout.startswith(before), "an earlier part's output differs"
    printed = stdout[len(before):][: len(outputs[part])]
    assert printed == outputs[part], (f"{SECTIONS[part]}: printed\n{printed}\nthe page says\n{outputs[part]}"
                                      + (f"\nstderr:\n{stderr[-2000:]}" if code else ""))
    if part == len(SECTIONS) - 1:
        assert stdout == before + outputs[part], "the code printed more than the page shows"
