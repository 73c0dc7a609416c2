"""bark's pictures drawn into axes of one's own (a notebook's, a paper's figure): every function
takes a matplotlib axes first and draws there, never a figure of its own::

    import matplotlib.pyplot as plt
    import bark
    from bark.analysis.pattern import Pattern
    from bark_cli.draw import PatternData, draw_histogram, draw_pattern, draw_radial

    outcome = bark.run(bark.Scene.from_toml("vertical"))
    stats = Pattern.of_simulation(outcome.sim).statistics(7)
    fig = plt.figure(figsize=(12, 4))
    draw_pattern(fig.add_subplot(1, 3, 1), PatternData.of(outcome.sim, 7))     # the unrolled trunk
    draw_radial(fig.add_subplot(1, 3, 2, projection="polar"), stats)          # Fig. 6B / 7B
    draw_histogram(fig.add_subplot(1, 3, 3, projection="polar"), stats)       # Fig. 6C / 7C

``draw_tree(ax, TreeData.of(sim, 7, scene.dome, scene.leaves))`` draws the tree from the side
(``bark_cli.tree_picture``; its extent and the leaves' width on the page from the tree and the axes
unless given); ``draw_quartet(ax, comparison, "orientation")`` and ``draw_pairing`` draw Fig. 8's
quartet analysis of four patterns (``bark.analysis.compare.compare``).  This module imports
matplotlib; ``bark`` itself never does.
"""

from bark_cli.figures import draw_histogram, draw_pairing, draw_quartet, draw_radial
from bark_cli.pictures import PatternData, TreeData
from bark_cli.plot import draw_pattern
from bark_cli.tree_picture import draw_tree

__all__ = ["PatternData", "TreeData", "draw_histogram", "draw_pairing", "draw_pattern", "draw_quartet", "draw_radial",
           "draw_tree"]
