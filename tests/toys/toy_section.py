"""A toy report section, the whole of it: the measured natural frequencies [Hz] per mode as bars."""

from flexmodal.reports.sections import Section, register_section

NAME = "toy"
TITLE = "Toy section: measured frequencies"


def figures(inputs):
    if inputs.measured is None:
        return []
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4, 3))
    ax = fig.add_subplot()
    frame = inputs.measured.frame
    ax.bar(range(len(frame)), frame["freq_hz"])
    ax.set_xlabel("row")
    ax.set_ylabel("frequency [Hz]")
    return [(fig, "Measured natural frequencies, one bar per row of the modal table")]


register_section(NAME, Section(TITLE, figures))
