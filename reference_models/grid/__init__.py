"""Networks of components: the WSCC 9-bus system (`wscc9`) and its monolithic reference simulation (`monolithic`)."""
