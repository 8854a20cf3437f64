"""What the studies' pictures share: one colour per discretisation, so that p = 4 is the
same green in the convergence study's plots and the cost study's."""

COLOURS = {"spectral": "#d62728", "p1": "#1f77b4", "p2": "#17becf", "p3": "#9467bd",
           "p4": "#2ca02c", "p6": "#8c564b", "p8": "#e377c2", "p1 graded": "#aec7e8",
           "p4 graded": "#98df8a", "p4 amg": "#bcbd22", "p4 centred 0.3": "#ffbb78",
           "p4 centred 0.5": "#ff7f0e", "p4 centred 0.7": "#d62728"}
