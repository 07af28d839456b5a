#!/usr/bin/env python3
"""Results pages: figures that name the run they came from.

Every figure the book quotes lives on a results page under `docs/results/`, written by this script
from one run of one command. The page is stamped with the command, the commit (and whether the tree
had changes), the machine (CPU model, CPUs, memory, kernel) and the date, and holds the command's
output as printed. A design page links to the results page instead of copying figures into prose,
so a figure can be traced to its run and rerun with one line.

usage:
  tools/results.py write [NAME...]   run each listed page's command (every page's when none is named)
                                     and write docs/results/NAME.md from its output
  tools/results.py list              each page with the commit and date it was written at
  tools/results.py check             every listed page written from its listed command, stamped, and
                                     in SUMMARY.md

`docs/results/pages.txt` lists the book's pages, one a line: NAME, TITLE and COMMAND (a shell
line, split as the shell would), separated by tabs.

The command runs in the repository's root. A command that fails writes no page (the old one stays).
"""

import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
import time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
PAGES = os.path.join(ROOT, "docs", "results")
STAMP = "<!-- results: "


def git(*args):
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True).stdout.strip()


def machine():
    cpu = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    mem = ""
    try:
        with open("/proc/meminfo") as f:
            kib = int(f.readline().split()[1])
            mem = f", {kib / 2**20:.0f} GiB"
    except (OSError, ValueError, IndexError):
        pass
    return f"{cpu}, {os.cpu_count()} CPUs{mem}, {platform.system()} {platform.release()}"


def read_stamp(path):
    with open(path) as f:
        for line in f:
            if line.startswith(STAMP):
                return json.loads(line[len(STAMP):].rsplit("-->", 1)[0])
    return None


def write(name, title, command):
    started = time.monotonic()
    print(f"results {name}: running {shlex.join(command)}", file=sys.stderr)
    proc = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = []
    for line in proc.stdout:
        sys.stderr.write(line)
        out.append(line)
    code = proc.wait()
    took = time.monotonic() - started
    if code != 0:
        print(f"results {name}: `{shlex.join(command)}` exited {code}: no page written", file=sys.stderr)
        return code
    commit = git("rev-parse", "--short=10", "HEAD") or "unknown"
    # The pages themselves are not the run's code: writing them one after another leaves them changed.
    dirty = bool(git("status", "--porcelain", "--untracked-files=no", "--", ".", ":!docs/results"))
    stamp = {
        "name": name,
        "title": title,
        "command": command,
        "commit": commit,
        "dirty": dirty,
        "machine": machine(),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "seconds": round(took),
    }
    text = "".join(out).rstrip("\n")
    fence = "````" if "```" in text else "```"
    page = (
        f"# {title}\n\n"
        f"{STAMP}{json.dumps(stamp)} -->\n"
        f"Written by `tools/results.py write {name}` from one run of\n\n"
        f"```bash\n{shlex.join(command)}\n```\n\n"
        f"- commit: `{commit}`{' with uncommitted changes' if dirty else ''}\n"
        f"- machine: {stamp['machine']}\n"
        f"- date: {stamp['date']} ({stamp['seconds']} s)\n\n"
        "The output, as printed:\n\n"
        f"{fence}text\n{text}\n{fence}\n"
    )
    os.makedirs(PAGES, exist_ok=True)
    with open(os.path.join(PAGES, f"{name}.md"), "w") as f:
        f.write(page)
    print(f"results {name}: docs/results/{name}.md at {commit}{' (dirty)' if dirty else ''}", file=sys.stderr)
    return 0


def listed():
    """The pages `pages.txt` lists: (name, title, command as argv)."""
    path = os.path.join(PAGES, "pages.txt")
    out = []
    with open(path) as f:
        for n, line in enumerate(f, 1):
            if not line.strip() or line.startswith("#"):
                continue
            parts = line.rstrip("\n").split("\t")
            if len(parts) != 3:
                raise SystemExit(f"{path}:{n}: NAME, TITLE and COMMAND separated by tabs; found {len(parts)} fields")
            out.append((parts[0], parts[1], shlex.split(parts[2])))
    return out


def pages():
    if not os.path.isdir(PAGES):
        return []
    return sorted(f[:-3] for f in os.listdir(PAGES) if f.endswith(".md"))


def main(argv):
    if not argv or argv[0] in ("-h", "--help"):
        sys.stdout.write(__doc__)
        return 0 if argv else 2
    verb, rest = argv[0], argv[1:]
    if verb == "write":
        todo = [p for p in listed() if not rest or p[0] in rest]
        unknown = set(rest) - {p[0] for p in todo}
        if unknown:
            print(f"write: not in docs/results/pages.txt: {sorted(unknown)}", file=sys.stderr)
            return 2
        for name, title, command in todo:
            code = write(name, title, command)
            if code:
                return code
        return 0
    if verb == "list":
        for name in pages():
            s = read_stamp(os.path.join(PAGES, f"{name}.md")) or {}
            print(f"{name:28} {s.get('commit', '?'):11} {s.get('date', '?'):21} {shlex.join(s.get('command', ['?']))}")
        return 0
    if verb == "check":
        bad = []
        with open(os.path.join(ROOT, "docs", "SUMMARY.md")) as f:
            summary = f.read()
        wanted = {name: (title, command) for name, title, command in listed()}
        for name in pages():
            if name not in wanted:
                bad.append(f"docs/results/{name}.md: not in docs/results/pages.txt")
        for name, (title, command) in wanted.items():
            path = os.path.join(PAGES, f"{name}.md")
            s = read_stamp(path) if os.path.exists(path) else None
            if not s or not s.get("command") or not s.get("commit"):
                bad.append(f"docs/results/{name}.md: not written, or no stamp naming its command and commit (tools/results.py write {name})")
            elif s["command"] != command:
                bad.append(f"docs/results/{name}.md: written by `{shlex.join(s['command'])}`, but pages.txt says `{shlex.join(command)}` (tools/results.py write {name})")
            if f"(results/{name}.md)" not in summary:
                bad.append(f"docs/results/{name}.md: not in docs/SUMMARY.md")
        for b in bad:
            print(b, file=sys.stderr)
        if not bad:
            print(f"results: {len(wanted)} pages, each written from its listed command and stamped with its commit")
        return 1 if bad else 0
    print(f"unknown verb {verb!r}; see --help", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
