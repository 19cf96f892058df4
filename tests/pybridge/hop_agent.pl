% Tartarus-style agent programs for test_bridge_platform.py.
%
% hop: started on one platform, it moves to the robot's platform
% (user:robot_port/1), reads the robot's Q-table, writes it back plus 1.0
% and records the sum it read with its payload fact carried/2.
% mailbox: a static agent that records the messages posted to it.
:- dynamic hop/3, carried/2, mailbox/3.

hop(guid, (Ip, Port), main) :-
    user:robot_port(Robot),
    (   Port == Robot
    ->  get_qtable(r1, qtable(S, V)),
        maplist([X, Y]>>(Y is X + 1.0), V, V2),
        set_qtable(r1, qtable(S, V2)),
        sum_list(V, Sum),
        (   carried(guid, C)
        ->  true
        ;   C = none
        ),
        assertz(user:agent_done(guid, Port, Sum-C))
    ;   move_agent(guid, (Ip, Robot))
    ).

mailbox(guid, _, main) :- !.
mailbox(guid, _, Text) :-
    assertz(user:got_mail(guid, Text)).
