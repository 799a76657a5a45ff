"""`cosim run --accuracy X`: the run's side of :mod:`cosim.studies.accurate`.

:meth:`Request.make` chooses the scheme and steps before the run (the
scene that runs); :meth:`Request.check`, once the run's error is estimated,
refines once where the estimate misses the accuracy, running the scene
again into the same folder, and adds ``accuracy.request`` to the summary.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

from cosim.errors import SimulationError

__all__ = ["Request"]


@dataclass
class Request:
    """An accuracy asked of one `cosim run`.

    Attributes
    ----------
    args
        The command's arguments (scene, variant, ``--set``).
    accuracy : float
    source : str
        ``--accuracy`` or ``scheme.accuracy``.
    scene
        The scene with the chosen scheme and steps.
    choice : cosim.studies.choose.Choice
    run : callable
        Runs a scene into the run's folder (set by the command).
    """

    args: object
    accuracy: float
    source: str
    scene: object
    choice: object
    run: object = field(default=None, repr=False)

    @classmethod
    def make(cls, args, scene) -> "Request":
        """The request of ``args`` (``--accuracy``, else the scene's
        ``scheme.accuracy``), its scheme and steps chosen.

        Raises
        ------
        SceneError
            If the model covers no contact of the scene, or no scheme meets
            the accuracy, or ``--no-estimate`` is given with an accuracy
            (nothing would check it).
        """
        from cosim.studies.accurate import asked, plan

        accuracy, source = asked(scene, args.accuracy)
        if args.no_estimate:
            from cosim.scene.checks import SceneError
            raise SceneError(scene.path, "scheme.accuracy" if source != "--accuracy" else "",
                             f"asks for an accuracy ({source}), which is checked against the "
                             f"run's error estimate: it cannot go with --no-estimate")
        scheme = args.scheme if args.scheme else None
        chosen, choice = plan(args.scene, args.variant, args.set or (), accuracy, scheme,
                              first=scene)
        return cls(args, accuracy, source, chosen, choice)

    @property
    def contact(self) -> str:
        """The contact the accuracy is asked of (the exit rates are read at
        its last release)."""
        return self.choice.knob.contact

    def check(self, res):
        """The run ``res`` (its summary's ``accuracy`` estimated) checked,
        and refined once when the estimate misses: the run kept, its summary
        with ``accuracy.request``."""
        from cosim.studies.accurate import refined, request_record
        from cosim.studies.estimate import estimate_errors

        estimated, why = self._verdict(res)
        first = None
        if estimated is not None and estimated > self.accuracy:
            first = (self.choice, estimated)
            args = self.args
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                scene, choice = refined(args.scene, args.variant, args.set or (), self.choice,
                                        estimated)
            again = self.run(scene)
            if not again.success:
                raise SimulationError(f"the refined run did not finish ({again.status}): "
                                      f"{again.message}")
            again.summary["accuracy"] = estimate_errors(scene, again, contact=self.contact)
            self.scene, self.choice, res = scene, choice, again
            estimated, why = self._verdict(res)
        res.summary["accuracy"]["request"] = request_record(
            self.accuracy, self.source, self.choice, estimated, why, first, self.scene)
        return res

    def _verdict(self, res):
        """:func:`cosim.studies.accurate.verdict` of ``res``; where the
        companion at 4x the step closed a contact another number of times,
        or did not finish (a step that long is unstable), a second one at 2x
        the step (half the run's cost, paid only then) gives the estimate,
        which replaces the summary's ``accuracy``."""
        from cosim.studies.accurate import verdict
        from cosim.studies.estimate import estimate_errors

        acc = res.summary["accuracy"]
        estimated, why = verdict(acc, self.choice, self.scene)
        counts = [c["count"]["robust"] for c in acc["contacts"].values()]
        failed = acc["companion"].get("status") not in ("finished", "not run")
        if estimated is None and not self.choice.knob.grasp and (failed or not all(counts)):
            closer = estimate_errors(self.scene, res, factor=2, contact=self.contact)
            estimated, why2 = verdict(closer, self.choice, self.scene)
            if estimated is not None:
                res.summary["accuracy"] = closer
                return estimated, why2
            why = f"{why}; at 2x the step too: {why2}"
        return estimated, why
