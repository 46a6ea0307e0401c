"""The natural spread of the face's proportions (`proportions.py`: size, and depth for breadth,
against the template's) over ICT Face Model subjects, the population the `face_size` and
`depth_ratio` gates must not refuse. Each subject's true template (`template_truth`) is measured
over the whole template and over the template vertices a framed capture sees (those matched on
the capture of each of three subjects, registered by `place_template`): a capture's reading
depends on how much of the face's side it sees.

Usage: .venv/bin/python bench/ict_proportions.py [--seeds 1000] [--first 5000] [--views 3000 3110 3051] [--workers 2]
       [--model NPZ | --model shipped]
"""

import argparse
import platform
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from cpapfit import __version__
from cpapfit.align.nonrigid import Registration
from cpapfit.similarity import fit_similarity
from cpapfit.ict import load_ict, random_subject, template_truth
from cpapfit.pipeline import place_template
from cpapfit.quality.proportions import proportions
from cpapfit.template import load_template
from ict_bench import model_argument, model_source
from ict_population import subject

PERCENTILES = (0.1, 1.0, 5.0, 50.0, 95.0, 99.0, 99.9)


def seen(job: tuple[int, Path | None]) -> np.ndarray:
    """(n,) bool: the template vertices the registration matched on subject `seed`'s framed capture."""
    seed, source = job
    return place_template(subject(seed, "capture", source)[0]).registration.valid


def measured(job: tuple[int, Path | None, np.ndarray]) -> np.ndarray:
    """(V, 2): subject `seed`'s true (size, depth ratio) over each of (V, n) vertex selections `views`."""
    seed, source, views = job
    template = load_template()
    truth = template_truth(random_subject(np.random.default_rng(seed), 0.0, load_ict(source))[0])
    fit = fit_similarity(template.vertices[::25], truth[::25])  # every 25th vertex: the pairwise scale is quadratic
    shape = [proportions(template.vertices, fit, Registration(truth, np.zeros(len(truth)), view)) for view in views]
    return np.array([(p.size, p.depth_ratio) for p in shape])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=1000)
    ap.add_argument("--first", type=int, default=5000)
    ap.add_argument("--views", type=int, nargs="+", default=[3000, 3110, 3051])
    ap.add_argument("--workers", type=int, default=2)
    model_argument(ap)
    args = ap.parse_args()
    source = model_source(args)
    print(f"cpapfit {__version__}, {platform.machine()}, Python {platform.python_version()}; ICT seeds "
          f"{args.first}-{args.first + args.seeds - 1} ({len(load_ict(source).identity)} identity modes); capture views of {args.views}")
    with ProcessPoolExecutor(args.workers) as pool:
        views = np.array(list(pool.map(seen, [(seed, source) for seed in args.views])))
        views = np.vstack([np.ones(views.shape[1], bool), views])
        jobs = [(seed, source, views) for seed in range(args.first, args.first + args.seeds)]
        values = np.array(list(pool.map(measured, jobs, chunksize=25)))  # (seeds, views, 2)
    print(f"\n| over | measure | min | {' | '.join(f'p{q:g}' for q in PERCENTILES)} | max |\n" + "|---" * (len(PERCENTILES) + 4) + "|")
    for v, label in enumerate(["whole template"] + [f"capture view of {seed}" for seed in args.views]):
        for m, name in enumerate(("face_size", "depth_ratio")):
            x = values[:, v, m]
            print(f"| {label} | {name} | {x.min():.3f} | {' | '.join(f'{p:.3f}' for p in np.percentile(x, PERCENTILES))} | {x.max():.3f} |")


if __name__ == "__main__":
    main()
