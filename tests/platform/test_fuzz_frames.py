"""Mutated binary frames from an authenticated peer leave the node alive (issue 32).

Real processes and sockets: ``dfrl bench fuzz``'s fuzzer (``experiments/tools/bench/fuzz.py``)
against a target node, with the C check and with its Prolog fallback, each frame followed by
a ping the same process must answer. The control: a body the fuzzer found on the previous
main, which aborts a ``swipl`` that decodes it unchecked, is refused by the check.

The seed is printed; ``DFRL_FUZZ_SEED`` and ``DFRL_FUZZ_FRAMES`` repeat or lengthen a run
(``dfrl bench fuzz --frames 20000`` is the long one).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from dfrl.experiments.tools.bench import fuzz
from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL

SEED = int(os.environ.get("DFRL_FUZZ_SEED", "20261203"))
FRAMES = int(os.environ.get("DFRL_FUZZ_FRAMES", "4000"))

#: A body of a ``variables`` seed frame with one byte changed (found by the fuzzer on main,
#: seed 2): ``copy_record: Assertion failed`` when decoded unchecked.
LETHAL = "622410037f030b0466757a7a0b04766172730d050b01670100010101000102010108010008010109"

DECODE = """
:- use_module({check!r}).
:- initialization(main, main).
main :-
    string_codes("{hex}", Hex), hex_bytes(Hex, Bytes), string_codes(S, Bytes),
    (   current_prolog_flag(argv, [checked|_])
    ->  catch(fast_term_decode(S, _, []), error(domain_error(fast_term_bytes, R), _),
              ( format("refused ~w~n", [R]), halt(3) ))
    ;   fast_term_serialized(_, S)
    ),
    format("decoded~n").
hex_bytes([], []).
hex_bytes([A, B|T], [X|Xs]) :- number_codes(X, [0'0, 0'x, A, B]), hex_bytes(T, Xs).
"""


def _decode(tmp_path: Path, checked: bool) -> subprocess.CompletedProcess[str]:
    script = tmp_path / "decode.pl"
    script.write_text(DECODE.format(check=str(PLATFORM_DIR / "fast_term_check.pl"), hex=LETHAL))
    assert SWIPL
    argv = [SWIPL, "-q", str(script)] + (["checked"] if checked else [])
    return subprocess.run(argv, capture_output=True, text=True, timeout=60)


@pytest.mark.skipif(SWIPL is None, reason="swipl not installed")
def test_control_lethal_body_aborts_unchecked_and_is_refused_checked(tmp_path: Path) -> None:
    # Execute: the same bytes decoded as main decoded them, then through the check
    raw = _decode(tmp_path, checked=False)
    checked = _decode(tmp_path, checked=True)
    # Assert: the unchecked decoder aborts the process; the check refuses the bytes
    assert raw.returncode in (-6, 134), (raw.returncode, raw.stderr[-500:])
    assert "Assertion failed" in raw.stderr
    assert checked.returncode == 3 and "refused bad_opcode" in checked.stdout, checked


def _fuzz(frames: int, native: bool) -> fuzz.FuzzResult:
    print(f"fuzz seed {SEED}, {frames} frames, native check {native}")
    return fuzz.run(
        fuzz.FuzzConfig(frames=frames, seed=SEED, max_s=120.0, native_check=native, max_crashes=1)
    )


@pytest.mark.skipif(SWIPL is None, reason="swipl not installed")
@pytest.mark.parametrize("native", [True, False], ids=["c_check", "prolog_check"])
def test_fuzzed_frames_leave_the_node_alive(native: bool) -> None:
    # Execute (the Prolog walk is slower on the deep bodies: fewer frames)
    frames = FRAMES if native else FRAMES // 4
    r = _fuzz(frames, native)
    # Assert: every frame sent, one node process throughout that answered every ping
    assert not r.crashes, f"seed {SEED}: {r.crashes[0]}"
    assert r.frames == frames and r.pings == frames, r.as_dict()
    assert len(r.node_pids) == 1
    # ... and the frames reached every layer: refused by the check, by the size and length
    # checks, as truncated, for their depth, and decoded and answered by the node
    kinds = set(r.replies)
    for expected in (
        "wire_error:syntax",
        "wire_error:protocol",
        "wire_error:truncated",
        "wire_error:too_deep",
        "wire_error:too_large",
        "error:domain_error",
    ):
        assert expected in kinds, (expected, r.replies)
