/*  Run by test_bridge_exit.py: bridge_stop_threads/3 again and again while
    detached threads (like the platform's bounds monitor, pool workers and
    janitor) are blocked and then aborted by it. Trials = argv[1]; prints
    `done N left L aborted A` (threads left over, threads aborted) and halts.

    Joining a detached thread that is exiting deadlocks SWI-Prolog 9.0.4;
    this loop found that in 600 trials 5 times out of 5 before the bridge
    stopped joining detached threads.
*/

:- initialization(main, main).
:- use_module('../../pybridge/robot_bridge').

waiter :-
    message_queue_create(Q),
    thread_get_message(Q, _).

trial(Left0-Aborted0, Left-Aborted) :-
    forall(between(1, 3, _), thread_create(waiter, _, [detached(true)])),
    sleep(0.001),
    bridge_stop_threads(2.0, Remaining, N),
    length(Remaining, L),
    Left is Left0 + L,
    Aborted is Aborted0 + N.

main :-
    current_prolog_flag(argv, [Arg]),
    atom_number(Arg, Trials),
    numlist(1, Trials, Ns),
    foldl([_, A0, A]>>trial(A0, A), Ns, 0-0, Left-Aborted),
    format("done ~w left ~w aborted ~w~n", [Trials, Left, Aborted]).
