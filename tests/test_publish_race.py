"""Two processes publishing output sets into one folder at the same moment, round after round:
after each round the folder holds exactly one complete set, the files of one of them and its
manifest, none of the other's, and nothing else (no staging folder, no lock file)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ROUNDS = 200
MANIFEST = "manifest.json"

# A worker: for each round number read on stdin, publish a set whose files say who wrote them in
# which round, then answer the number. Some names are its own, one is shared with the other worker.
WORKER = """
import sys
from pathlib import Path
from diffsense import runtime

name, out = sys.argv[1], Path(sys.argv[2])
print("ready", flush=True)
for line in sys.stdin:
    with runtime.output_set(out) as staging:
        for rel in sorted(set(sys.argv[3:])):
            (staging / rel).parent.mkdir(parents=True, exist_ok=True)
            (staging / rel).write_text(f"{name} {line.strip()}")
    print(line.strip(), flush=True)
"""
SETS = {
    "a": ["shared.txt", "a0.txt", "a1.txt", "a2.txt", "a3.txt", "plots/a.png", "plots/both.png"],
    "b": ["shared.txt", "b0.txt", "b1.txt", "b2.txt", "b3.txt", "plots/b.png", "plots/both.png"],
}


def _folder(out: Path) -> tuple[set[str], dict[str, str]]:
    """Every entry in `out` (hidden ones too) and the text of each file."""
    entries = {p.relative_to(out).as_posix() for p in out.rglob("*")}
    return entries, {rel: (out / rel).read_text() for rel in entries if (out / rel).is_file()}


def _one_complete_set(out: Path, round_: int) -> str | None:
    """Which worker's set `out` holds whole after `round_`, or None if it holds anything else."""
    entries, texts = _folder(out)
    listed = json.loads(texts.pop(MANIFEST, "{}")).get("files", [])
    for name, files in SETS.items():
        folders = {str(Path(f).parent) for f in files} - {"."}
        if (sorted(listed) == sorted(files) and entries == {*files, *folders, MANIFEST}
                and set(texts.values()) == {f"{name} {round_}"}):
            return name
    return None


def test_two_processes_publishing_into_one_folder_leave_one_complete_set(tmp_path):
    out = tmp_path / "out"
    workers = [subprocess.Popen([sys.executable, "-c", WORKER, name, str(out), *files], cwd=ROOT, text=True,
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
               for name, files in SETS.items()]
    try:
        for w in workers:
            assert w.stdout.readline() == "ready\n", w.communicate(timeout=60)[1][-2000:]
        winners, bad = [], []
        for k in range(ROUNDS):
            for w in workers:  # both start at once; the staging and the publish race
                w.stdin.write(f"{k}\n")
                w.stdin.flush()
            for w in workers:
                assert w.stdout.readline() == f"{k}\n", w.communicate(timeout=60)[1][-2000:]
            winner = _one_complete_set(out, k)
            winners.append(winner)
            if winner is None:
                bad.append((k, sorted(_folder(out)[0])))
    finally:
        for w in workers:
            w.kill()
            w.communicate()
    assert not bad, f"{len(bad)}/{ROUNDS} rounds left something other than one set, e.g. {bad[0]}"
    assert set(winners) <= set(SETS)
