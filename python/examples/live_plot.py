#!/usr/bin/python3
"""Live plot of θ̂ from scp-estimatord (matplotlib): one panel per parameter, ±σ shaded, θ as a
dashed line when the daemon runs the simulated actuator.

    python3 live_plot.py [--socket PATH] [--rate HZ] [--window S]
"""

import argparse
import collections
import threading

import matplotlib.pyplot as plt
from matplotlib.animation import FuncAnimation

from scp_estimator import PARAMETERS, Client


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--socket", help="daemon socket (default: $SCP_ESTIMATOR_SOCKET or "
                        "/run/scp-estimator/scp-estimator.sock)")
    parser.add_argument("--rate", type=float, default=10.0, help="estimates per second")
    parser.add_argument("--window", type=float, default=120.0, help="seconds shown")
    args = parser.parse_args()

    history = collections.deque(maxlen=int(args.window * args.rate) + 1)
    lock = threading.Lock()

    # The stream is read on its own thread so that a slow redraw never backs up the socket.
    def receive():
        with Client(args.socket) as client:
            for estimate in client.watch(rate_hz=args.rate):
                with lock:
                    history.append(estimate)

    threading.Thread(target=receive, daemon=True).start()

    figure, axes = plt.subplots(3, 2, sharex=True, figsize=(10, 8))
    axes = axes.ravel()

    def redraw(_frame):
        with lock:
            data = list(history)
        if not data:
            return
        t = [e["t"] for e in data]
        for i, ax in enumerate(axes):
            ax.clear()
            hat = [e["theta_hat"][i] for e in data]
            sigma = [e["sigma"][i] if e["sigma"][i] is not None else 0.0 for e in data]
            ax.plot(t, hat, label="θ̂")
            ax.fill_between(t, [h - s for h, s in zip(hat, sigma)],
                            [h + s for h, s in zip(hat, sigma)], alpha=0.3, label="±σ")
            if "theta_true" in data[-1]:
                ax.axhline(data[-1]["theta_true"][i], linestyle="--", color="k", label="θ")
            ax.set_title(PARAMETERS[i])
        axes[-1].set_xlabel("loop time, s")
        axes[-2].set_xlabel("loop time, s")
        axes[0].legend(loc="best")

    _animation = FuncAnimation(figure, redraw, interval=500, cache_frame_data=False)
    plt.tight_layout()
    plt.show()


if __name__ == "__main__":
    main()
