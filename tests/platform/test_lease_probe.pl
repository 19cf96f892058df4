/*  plunit tests of what a stop tells a lease holder that lost its agent
    (issue 33): a stop the agent wrote less than a lease ago answers
    written(Epoch, Ago), and a holder whose lost stop is silent takes it
    for a sign of life (its own cut, not the agent's) and does not
    resurrect; where the lost stop is gone, such a write is no news.
    Several nodes in one process, on OS-chosen localhost ports.
    Run: swipl -g run_tests -t halt test_lease_probe.pl
*/
:- use_module('../../platform_pl/tartarus').
:- use_module('../../platform_pl/dfrl_agent/dfrl_agent').
:- use_module('../../platform_pl/dfrl_agent/dfrl_lease').
:- use_module('../../platform_pl/dfrl_agent/lease_book').
:- use_module('../../platform_pl/dfrl_agent/lease_watch').
:- use_module(library(plunit)).

lease(1.0).

start(Node) :-
    lease(L),
    node_start(localhost:0, Node, [token(k), default(false), connect_timeout(1),
                                   reply_timeout(2), lease_s(L)]).

stop_all(Nodes) :- forall(member(N, Nodes), catch(node_stop(N), _, true)).

address(Node, Host:Port) :- node_property(Node, address(Host:Port)).

%   A checkpoint's record as lease_watch reads it: the itinerary's stops.
record(Stops, agent(fx, _, mobile, [], [k], [], [(dfrl_plan(fx, plan(It, 3, 0, log, [])) :- true)], 0)) :-
    findall(stop(H, P, r), member(H:P, Stops), It).

wrote(Node, Epoch, Round) :-
    lease_note_write(Node, r0, [agent(fx), epoch(Epoch), round(Round), robot(r0)]).

:- begin_tests(lease_probe).

test(written_just_now, [cleanup(stop_all([A, B])), Answer = written(1, _)]) :-
    start(A), start(B),
    wrote(B, 1, 3),
    address(B, BAddr),
    quick_call(A, [k], BAddr, probe(fx, 1, 1), Answer),
    Answer = written(_, Ago),
    lease(L),
    assertion(Ago < L).

test(written_by_a_lower_epoch_is_unknown, [cleanup(stop_all([A, B])), Answer == unknown]) :-
    start(A), start(B),
    wrote(B, 1, 3),
    address(B, BAddr),
    quick_call(A, [k], BAddr, probe(fx, 2, 1), Answer).

test(written_a_lease_ago_is_unknown, [cleanup(stop_all([A, B])), Answer == unknown]) :-
    start(A), start(B),
    wrote(B, 1, 3),
    lease(L), Wait is L + 0.1, sleep(Wait),
    address(B, BAddr),
    quick_call(A, [k], BAddr, probe(fx, 1, 1), Answer).

%   The holder A lost the agent at Dest (not listening: the answer does not
%   matter here, others_know only asks the other stops B and C), Dest
%   being silent or gone; B written by the agent just now if Write is true.
ask_others(Dest_, Write, BAddr, Known, Answered) :-
    start(A), start(B), start(C),
    maplist(address, [A, B, C], [AAddr, BAddr, CAddr]),
    Dest = localhost:1,
    record([AAddr, BAddr, CAddr, Dest], Record),
    (   Write == true -> wrote(B, 1, 3) ; true ),
    call_cleanup(lease_watch:others_know(A, Dest, Dest_, AAddr, Record, fx, 1, 1, Known, Answered),
                 stop_all([A, B, C])).

test(silent_stop_and_a_fresh_write_is_life, Known = lives(BAddr, _)) :-
    ask_others(silent, true, BAddr, Known, Answered),
    assertion(Answered >= 1).

test(gone_stop_and_a_fresh_write_is_no_news, Known == max_epoch(1)) :-
    ask_others(gone, true, _, Known, Answered),
    assertion(Answered =:= 2).

test(silent_stop_and_no_write_is_no_news, Known == max_epoch(1)) :-
    ask_others(silent, false, _, Known, _).

:- end_tests(lease_probe).
