:- consult('../../tartarus.pl').
:- consult(tour).
node_label(alpha).
:- start_tartarus(localhost, 7001, 1111).
:- create_mobile_agent(tourist, (localhost, 7001), tour, [1111]),
   add_payload(tourist, [(collected, 2)]),
   execute_agent(tourist, (localhost, 7001), tour).
