"""Checks on compiled XLA programs (``jax.jit(f).lower(...).compile().as_text()``)."""

from __future__ import annotations

import re

_COMPUTATION = re.compile(r"^(?:ENTRY )?%?([\w.\-]+) .*\{\s*$")
_INSTRUCTION = re.compile(r"^\s+(?:ROOT )?%([\w.\-]+) = .*?\s[\w\-]+\((.*?)\)(?:,|$)")


def unordered_lapack_calls(hlo_text: str) -> tuple[int, int]:
    """``(calls, unordered_pairs)``: how many LAPACK custom calls the compiled program text
    holds, and how many pairs of them in one computation are independent (neither reaches the
    other through operands), so that XLA's CPU runtime may run them side by side. Two LAPACK
    calls side by side on the 2-thread pool were seen to deadlock (every thread in a futex
    wait; issues 24 and 26): programs that must never hang keep ``unordered_pairs == 0``."""
    comps: dict[str, dict[str, tuple[list[str], bool]]] = {}
    cur = None
    for line in hlo_text.splitlines():
        if not line.startswith(" "):
            m = _COMPUTATION.match(line)
            if m:
                cur = comps.setdefault(m.group(1), {})
            continue
        m = _INSTRUCTION.match(line)
        if cur is not None and m:
            name, args = m.groups()
            cur[name] = (re.findall(r"%([\w.\-]+)", args), 'custom_call_target="lapack' in line)
    n_calls = n_bad = 0
    for ins in comps.values():
        calls = [n for n, (_, lapack) in ins.items() if lapack]
        n_calls += len(calls)
        ancestors: dict[str, set[str]] = {}
        for c in calls:
            seen: set[str] = set()
            stack = [c]
            while stack:
                for o in ins.get(stack.pop(), ((), False))[0]:
                    if o not in seen:
                        seen.add(o)
                        stack.append(o)
            ancestors[c] = seen
        for i, a in enumerate(calls):
            for b in calls[i + 1 :]:
                n_bad += a not in ancestors[b] and b not in ancestors[a]
    return n_calls, n_bad
