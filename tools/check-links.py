#!/usr/bin/env python3
"""Checks the relative links of the README, the contributing guide, the changelog and the book
(`docs/`): every linked file exists, and every `#anchor` names a heading of its page (GitHub's
slugs, which mdBook's match). Links inside code are not links. Exits 1 naming each dead link.

usage: tools/check-links.py [ROOT]   (default: the repository this script is in)
"""
import os
import re
import sys

root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), ".."))
pages = ["README.md", "CONTRIBUTING.md", "CHANGELOG.md"]
for d, _, files in os.walk(os.path.join(root, "docs")):
    pages += [os.path.relpath(os.path.join(d, f), root) for f in files if f.endswith(".md")]

LINK = re.compile(r"\[([^\]]*)\]\(([^)\s]+)\)")


def prose(text):
    """The text outside fenced code blocks and inline code spans."""
    out, fenced = [], False
    for line in text.split("\n"):
        if line.lstrip().startswith("```"):
            fenced = not fenced
            out.append("")
            continue
        out.append("" if fenced else re.sub(r"`[^`]*`", "", line))
    return "\n".join(out)


def slug(heading):
    t = heading.strip().lower().replace("`", "")
    t = re.sub(r"[^\w\- ]", "", t)
    return t.replace(" ", "-")


anchors_of = {}


def anchors(path):
    if path not in anchors_of:
        seen, found, fenced = {}, set(), False
        for line in open(path, encoding="utf-8"):
            if line.lstrip().startswith("```"):
                fenced = not fenced
            if fenced or not line.startswith("#"):
                continue
            s = slug(line.lstrip("#"))
            n = seen.get(s, 0)
            seen[s] = n + 1
            found.add(s if n == 0 else f"{s}-{n}")
        anchors_of[path] = found
    return anchors_of[path]


dead = []
for page in pages:
    path = os.path.join(root, page)
    for n, line in enumerate(prose(open(path, encoding="utf-8").read()).split("\n"), 1):
        for _, target in LINK.findall(line):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):
                continue
            file, _, anchor = target.partition("#")
            dest = os.path.normpath(os.path.join(os.path.dirname(path), file)) if file else path
            if not os.path.exists(dest):
                dead.append(f"{page}:{n}: {target}: no such file")
            elif anchor and dest.endswith(".md") and anchor not in anchors(dest):
                dead.append(f"{page}:{n}: {target}: no heading #{anchor} in {os.path.relpath(dest, root)}")
for d in dead:
    print(d)
print(f"links: {len(pages)} pages checked, {len(dead)} dead")
sys.exit(1 if dead else 0)
