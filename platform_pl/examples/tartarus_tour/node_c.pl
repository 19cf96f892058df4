:- consult('../../tartarus.pl').
:- consult(tour).
node_label(charlie).
:- start_tartarus(localhost, 7003, 1111).
:- create_static_agent(mailbox, (localhost, 7003), mailbox, [1111]).
