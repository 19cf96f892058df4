% A Tartarus-style agent program: consulted on every node of the tour.
% The agent visits 7001 -> 7002 -> 7003, collects each node's label,
% posts a greeting to the mailbox agent on 7003, comes home to 7001,
% prints what it collected and sends a clone to 7002.

:- dynamic tour/3, collected/2, mailbox/3, mailbox/4.

collected(guid, []).

tour(guid, (_Ip, Port), main) :-            % a clone: the tour is done
    collected(guid, L), length(L, N), N >= 4, !,
    node_label(Label),
    format("clone ~w resting at ~w (~w) with ~w~n", [guid, Label, Port, L]).
tour(guid, (Ip, Port), main) :-
    node_label(Label),
    format("tour ~w visiting ~w (~w)~n", [guid, Label, Port]),
    retract(collected(guid, L)),
    assertz(collected(guid, [Label|L])),
    (   Port == 7003
    ->  post_agent(platform, (Ip, 7003), [mailbox, mailbox, (Ip, 7003), hello, guid])
    ;   true
    ),
    next_stop(Port, L, Next),
    (   Next == home
    ->  collected(guid, All), reverse(All, InOrder),
        format("tour ~w home with ~w~n", [guid, InOrder]),
        clone_agent(guid, (Ip, 7002), Clone),
        format("sent clone ~w~n", [Clone])
    ;   move_agent(guid, (Ip, Next))
    ).

next_stop(7001, [], 7002).
next_stop(7002, _, 7003).
next_stop(7003, _, 7001).
next_stop(7001, [_|_], home).

mailbox(guid, _, main).
mailbox(guid, _, Text, From) :-
    format("mailbox got ~w from ~w~n", [Text, From]).
