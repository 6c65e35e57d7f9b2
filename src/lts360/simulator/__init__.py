"""Physics: scene → image with Mitsuba 3 / Dr.Jit.

The entry point sets the Mitsuba variant (``mitsuba.set_variant``) before calling
:func:`lts360.simulator.frame.simulate_frame` or :func:`lts360.simulator.render.render_radiance`;
no module here sets it or imports Mitsuba at import time.
"""
