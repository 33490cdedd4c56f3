"""Preview figure of a dataset: a few trajectories of each family, inputs and states."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from reference_models.files import atomic_path


def plot_preview(directory: str | Path, split: str = "train", per_family: int = 2) -> Path:
    """Writes `preview.png` in the dataset directory (inputs and states over time); returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .datasets import load_split

    directory = Path(directory)
    data = load_split(directory, split)
    families = list(dict.fromkeys(data["family"].tolist()))
    picks = [i for f in families for i in np.nonzero(data["family"] == f)[0][:per_family]]
    component = data["component"]
    panels = [(data["u"], i, q.name, q.unit) for i, q in enumerate(component.inputs)]
    panels += [(data["x"], i, q.name, q.unit) for i, q in enumerate(component.states)]
    fig, axes = plt.subplots(2, (len(panels) + 1) // 2, figsize=(13, 6.5), sharex=True, squeeze=False)
    colors = {f: plt.cm.tab10(k % 10) for k, f in enumerate(families)}
    for ax, (arr, i, name, unit) in zip(axes.flat, panels):
        for j in picks:
            ax.plot(data["t"], arr[j, :, i], color=colors[data["family"][j]], lw=1)
        ax.set_title(name)
        ax.set_ylabel(unit)
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("t [s]")
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    handles = [plt.Line2D([], [], color=c, label=f) for f, c in colors.items()]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), frameon=False)
    fig.suptitle(f"{directory.name}: {split} split, {per_family} trajectories per family")
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    path = directory / "preview.png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return path
