"""Talking over Zenoh and being a process: the wire's messages (wire), the key expressions
(keys), the Bus and its Zenoh and in-memory implementations (bus), mutual TLS and access
control (secure), and what every command's process shares (procutil: arguments, signals,
logging, Zenoh configuration).  Imports util, math and scenario."""
