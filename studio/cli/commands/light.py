"""``studio light SESSION``: estimate the light(s) from the bodies and their cast shadows (thesis §5.7)."""

from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "light",
        help="estimate the light(s) casting the shadows from the fitted bodies (thesis ch. 5)",
        description=(
            "Estimate the point or directional light(s) whose shadows of the fitted bodies best match "
            "the segmented shadows over several frames (eq. 5.9): a coarse grid of 288 hypotheses, 7x7x7 "
            "refinements, then the posterior by MCMC (emcee) for credible intervals. Writes "
            "SESSION/light/light.json (kind, position or direction, direction_ci_deg, distance_ci, the "
            "samples' summary, timings)."
        ),
    )
    p.add_argument("session", type=Path, help="capture-session folder (calibrated, segmented and fitted)")
    p.add_argument("--frames", default=None,
                   help="frames to use: START:STOP[:STEP] or a comma list (default: up to 10 fitted frames, evenly spread)")  # fmt: skip
    p.add_argument("--kind", default="auto", choices=["point", "directional", "auto"],
                   help="light model; auto estimates both and keeps the one the BIC prefers (default: %(default)s)")  # fmt: skip
    p.add_argument("--lights", type=int, default=1, choices=[1, 2], help="number of lights (default: %(default)s)")
    p.add_argument("--bodies", default="fit", choices=["fit", "truth"],
                   help="bodies casting the shadows: fitted (fit/) or, for a simulated session, the truth")  # fmt: skip
    p.add_argument("--shadows", default="segmentation", choices=["segmentation", "truth"],
                   help="observed shadows: the segmentation's label 2 or, for a simulated session, the true labels")  # fmt: skip
    p.add_argument("--workers", type=int, default=1,
                   help="processes scoring the hypotheses (default: %(default)s; the compiled objective scores 10 "
                        "frames in a few CPU seconds, less than starting more processes costs)")  # fmt: skip
    p.add_argument("--refine-floor", action="store_true",
                   help="also refine the ground plane from the shadows (tilt and height about the calibration's; "
                        "recorded in light.json under 'floor', used by `studio fit --shadows`)")  # fmt: skip
    p.add_argument("--steps", type=int, default=40, help="MCMC steps per walker (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the sampler (default: %(default)s)")
    p.add_argument("--out", type=Path, default=None,
                   help="read fit/ and segmentation/ from, and write light/ into, this folder instead of the session")  # fmt: skip
    p.set_defaults(func=run)


def run(args) -> int:
    from studio.cli import CommandError, open_workspace
    from studio.light import LightError, estimate_session_light
    from studio.workspace import WorkspaceError
    from studio.workspace.frames import select_frames

    if args.workers < 1:
        raise CommandError(f"--workers must be >= 1, got {args.workers}")
    if args.steps < 10:
        raise CommandError(f"--steps must be >= 10, got {args.steps}")
    ws = open_workspace(args.session, out=args.out)
    frames = select_frames(args.frames, ws.frame_indices)
    try:
        out = estimate_session_light(ws, frames=frames, kind=args.kind, n_lights=args.lights, bodies=args.bodies,
                                     shadows=args.shadows, workers=args.workers, seed=args.seed, n_steps=args.steps,
                                     refine_floor=args.refine_floor)
    except (LightError, WorkspaceError) as exc:
        raise CommandError(str(exc)) from None
    for i, light in enumerate(out["lights"]):
        where = (f"at {[round(v, 3) for v in light['position']]} m, distance {light['distance_m']:.2f} m "
                 f"(95% CI {light['distance_ci'][0]:+.1f}% .. {light['distance_ci'][1]:+.1f}%)"
                 if light["kind"] == "point" else f"towards {[round(v, 4) for v in light['direction']]}")
        print(f"light {i + 1}: {light['kind']} {where}, direction ±{light['direction_ci_deg']:.2f}° (95%)")
    if "floor" in out:
        fl = out["floor"]
        print(f"floor: tilted {fl['tilt_deg']:.2f}° from the calibration's, {1000 * fl['height_at_centre_m']:+.1f} mm "
              "at the subject")
    s = out["samples_summary"]
    print(f"frames {out['frames']}; {out['n_evaluations']} evaluations, effective sample size {s['effective_sample_size']:.0f}, "
          f"{out['timings']['total']:.1f} s; written {ws.layout.light_json}")
    return 0
