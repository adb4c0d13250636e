"""A behaviour that holds in most of a few runs: how a physical outcome is asserted on any CPU, where
one contact-rich rollout can flip with floating-point rounding."""

RUNS, MAJORITY = 3, 2


def holds_in_most(attempt, runs: int = RUNS, majority: int = MAJORITY) -> tuple[bool, list]:
    """(whether attempt(k) -> (ok, detail) held in at least `majority` of `runs` runs, the (ok, detail)
    of each run made). Stops as soon as the answer is known."""
    outcomes = []
    for run in range(runs):
        outcomes.append(attempt(run))
        held = sum(ok for ok, _ in outcomes)
        if held >= majority or held + runs - len(outcomes) < majority:
            break
    return sum(ok for ok, _ in outcomes) >= majority, outcomes
