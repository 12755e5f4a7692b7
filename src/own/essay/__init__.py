"""Pure-Python broad phases that follow the essay's method, one Python object per particle.

They are the baseline that shows what compiling and exact pair sets gain. The defects of the
essay's printed code (quadtree containment test, grid index wrap-around) are fixed here; the
duplicate tests caused by 9-cell insertion are kept and counted, because they are the method.
"""
