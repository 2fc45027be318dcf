"""The weathers a script's header draws from, by the weather a description gives."""

__all__ = ["WEATHERS"]

WEATHERS = {
    "clear": ["'ClearNoon'", "'ClearSunset'", "'CloudyNoon'"],
    "rain": ["'WetNoon'", "'SoftRainNoon'", "'MidRainyNoon'", "'HardRainNoon'"],
    "night": ["'ClearNight'", "'CloudyNight'", "'WetNight'"],
    "fog": ["'CloudyNoon'", "'WetCloudyNoon'", "'CloudySunset'"],
    "any": ["'ClearNoon'", "'CloudyNoon'", "'WetNoon'", "'ClearSunset'", "'WetCloudySunset'", "'SoftRainNoon'"],
}
