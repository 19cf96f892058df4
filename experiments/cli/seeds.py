"""The seeds of a study on the command line, said one unambiguous way (``--seeds``,
``--n-seeds``, ``--seed``): shared by ``dfrl paper``, ``speedup``, ``sweep``, ``transfer``,
``transfer-study`` and ``hetero``."""

from __future__ import annotations

import argparse


def add_seed_arguments(p: argparse.ArgumentParser, default: int) -> None:
    """The seeds of a study, said one unambiguous way: ``--seeds S1 S2 ...`` (a list of at
    least two), ``--n-seeds K`` (the seeds 1..K) or ``--seed S`` (that seed alone); default
    ``default`` seeds 1..default. :func:`chosen_seeds` reads them."""
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        default=None,
        metavar="S",
        help="the seeds, listed (at least two; a lone value is refused as "
        "ambiguous: use --n-seeds K or --seed S)",
    )
    g.add_argument(
        "--n-seeds", type=int, default=None, metavar="K", help=f"K seeds: 1..K (default: {default})"
    )
    g.add_argument("--seed", type=int, default=None, metavar="S", help="one seed, S alone")
    p.set_defaults(default_seed_count=default)


def chosen_seeds(args: argparse.Namespace) -> tuple[int, ...]:
    """The seeds :func:`add_seed_arguments` parsed.

    Raises
    ------
    ValueError
        ``--seeds`` with one value (a count or a seed?), a seed repeated, a count below 1 or a
        negative seed.
    """
    if args.seeds is not None:
        if len(args.seeds) == 1:
            k = args.seeds[0]
            raise ValueError(
                f"--seeds {k} is ambiguous: write --n-seeds {k} for the seeds "
                f"1..{k}, or --seed {k} for seed {k} alone"
            )
        twice = sorted({s for s in args.seeds if args.seeds.count(s) > 1})
        if twice:
            raise ValueError(f"--seeds: seed {', '.join(map(str, twice))} given twice")
        seeds = tuple(args.seeds)
    elif args.seed is not None:
        seeds = (args.seed,)
    else:
        k = args.default_seed_count if args.n_seeds is None else args.n_seeds
        if k < 1:
            raise ValueError(f"--n-seeds {k}: at least 1")
        seeds = tuple(range(1, k + 1))
    if min(seeds) < 0:
        raise ValueError(f"seeds are >= 0, got {min(seeds)}")
    return seeds
