"""The physics of flight below identification: the atmosphere, the ascent, how the roll
model scales with the airspeed, and the turbulence models a flight meets.

* :mod:`rocketroll_physics.atmosphere` -- the International Standard Atmosphere;
* :mod:`rocketroll_physics.ascent` -- the 1-D ascent of a sounding rocket (thrust,
  burning mass, drag) and its recorded or simulated profiles;
* :mod:`rocketroll_physics.scaling` -- the airspeed scaling of the roll model (eq. 4-8
  or measured exponents), a fit's reference, and the Mach limit of the subsonic model;
* :mod:`rocketroll_physics.ou` -- the Ornstein-Uhlenbeck process averaged over an
  interval, exactly (the turbulence prior of the flight method and the Dryden draws);
* :mod:`rocketroll_physics.dryden` -- the MIL-F-8785C Dryden roll gust;
* :mod:`rocketroll_physics.flown` -- a tunnel trace flown through a frozen field
  (Taylor), time compressed and scaled with the airspeed.

It knows nothing of recordings, fits or databases: identification, the database, the
environments and the controllers all build on it.
"""
