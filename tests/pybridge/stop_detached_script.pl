/*  Run by test_bridge_exit.py: bridge_stop_threads/3 again and again while
    detached threads (like the platform's bounds monitor, pool workers and
    janitor) are blocked and then aborted by it. Trials = argv[1]; prints
    `done N` and the threads left over, and halts.

    Joining a detached thread that is exiting deadlocks SWI-Prolog 9.0.4;
    this loop found that in 600 trials 5 times out of 5 before the bridge
    stopped joining detached threads.
*/

:- initialization(main, main).
:- use_module('../../pybridge/robot_bridge').

waiter :-
    message_queue_create(Q),
    thread_get_message(Q, _).

trial(Left0, Left) :-
    forall(between(1, 3, _), thread_create(waiter, _, [detached(true)])),
    sleep(0.001),
    bridge_stop_threads(2.0, Remaining, _),
    length(Remaining, N),
    Left is Left0 + N.

main :-
    current_prolog_flag(argv, [Arg]),
    atom_number(Arg, Trials),
    numlist(1, Trials, Ns),
    foldl([_, L0, L]>>trial(L0, L), Ns, 0, Left),
    format("done ~w left ~w~n", [Trials, Left]).
