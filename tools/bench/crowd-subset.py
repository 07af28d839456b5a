#!/usr/bin/env python3
"""Writes a scenario of the first N users of a scenario and the phases about those users only.

Usage: crowd-subset.py SCENARIO OUT N  (the crowd benchmarks' --sites N)
"""
import re
import sys

text = open(sys.argv[1]).read()
head, *blocks = re.split(r'(?m)^(?=\[\[(?:site|phase)\]\])', text)
sites = [b for b in blocks if b.startswith("[[site]]")][:int(sys.argv[3])]
names = [re.search(r'(?m)^name\s*=\s*"([^"]+)"', s).group(1) for s in sites]
phases = [b for b in blocks if b.startswith("[[phase]]")
          and all(n in names for n in re.findall(r'"(user\d+)"', b))]
open(sys.argv[2], "w").write(head + "".join(sites) + "".join(phases))
