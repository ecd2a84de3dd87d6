"""HTTP routers: HTTP only, every decision is a service's."""
