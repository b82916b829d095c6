"""The celestial fix (``starnav locate``, zenith-fixer) and three-star pointing."""
