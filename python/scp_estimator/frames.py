"""Estimates as flat rows: for CSV writers, plots and pandas."""

# θ = [b/m, α1/m, k/m, α2/m, λ/Cth, 1/(R·Cth)], in the order of ESTIMATE.theta_hat.
PARAMETERS = ("b/m", "alpha1/m", "k/m", "alpha2/m", "lambda/Cth", "1/(R*Cth)")

_VECTORS = ("theta_hat", "sigma", "theta_true", "rel_error")


def flatten(estimate):
    """One ESTIMATE object as a flat dict: t, updates, skipped, theta_hat[b/m], sigma[b/m], ...,
    converged.mechanical, excitation.thermal, physical.b, ... Members the daemon omitted are
    absent; null elements (σ before enough data) become None."""
    row = {}
    for key, value in estimate.items():
        if key == "class":
            continue
        if key in _VECTORS and isinstance(value, list):
            for name, element in zip(PARAMETERS, value):
                row["%s[%s]" % (key, name)] = element
        elif isinstance(value, dict):
            for inner, element in value.items():
                row["%s.%s" % (key, inner)] = element
        elif isinstance(value, list):
            for i, element in enumerate(value):
                row["%s[%d]" % (key, i)] = element
        else:
            row[key] = value
    return row


def to_dataframe(estimates):
    """A pandas DataFrame of ESTIMATE objects (e.g. from Client.watch), indexed by t."""
    try:
        import pandas
    except ImportError as error:
        raise ImportError(
            "to_dataframe() needs pandas (apt install python3-pandas); "
            "scp_estimator.flatten() gives the same rows as dicts"
        ) from error
    frame = pandas.DataFrame([flatten(e) for e in estimates])
    if "t" in frame.columns:
        frame = frame.set_index("t")
    return frame
