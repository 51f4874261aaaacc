"""The link between the hosts: messages, the Zenoh link, receive filters, injection, auth,
phase lock, router, the passivity layer on the wire."""
