"""Terminal progress bars (rich) for long stage loops, as ProgressFactory callbacks."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from physanim.pipeline.context import ProgressFactory, ProgressFn


@contextlib.contextmanager
def rich_progress(console: Console | None = None) -> Iterator[ProgressFactory]:
    """Context yielding a factory: ``factory("simulate")`` returns a (done, total) callback."""
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=False,
    ) as bar:

        def factory(description: str) -> ProgressFn:
            task = bar.add_task(description, total=None)

            def update(done: int, total: int) -> None:
                bar.update(task, completed=done, total=total)

            return update

        yield factory
