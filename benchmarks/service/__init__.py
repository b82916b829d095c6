"""``starnav serve`` under load and through a real nova client."""
