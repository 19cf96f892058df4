:- module(timed_connect,
          [ timed_connect/4             % +Address, -StreamPair, +Timeout, +Options
          ]).
:- use_module(library(socket), [tcp_connect/3]).
%   Eager imports (not autoload/2): see node_connection.pl.

/** <module> A TCP connect bounded in time without signals

A connect to a host that does not answer (its link cut, its packets
dropped) blocks in connect(2) while the kernel resends its SYN, about
two minutes. call_with_time_limit/2 cannot cut that short in a process
whose Prolog runs without signal handling: pyswip starts the embedded
Prolog of every robot process with `--nosignals`, so the alarm cannot
interrupt the system call (measured in namespaces: a connect with a 2 s
limit to a host cut off had not returned after 60 s, and a federation
waited 35-70 s for a move its skip time bounded to 4 s).

timed_connect/4 therefore connects in a short-lived thread and waits for
its answer on a message queue with a timeout, which needs no signal. On
a timeout the waiting thread gives up and leaves; the connecting thread
ends when the kernel gives up, and closes the connection if it was made
too late. The hand-over of a late connection and the removal of the
queue happen under one mutex, so no connection is left open unowned.
*/

%!  timed_connect(+Address, -StreamPair, +Timeout, +Options) is det.
%
%   tcp_connect(Address, StreamPair, Options) done within Timeout
%   seconds.
%
%   @error time_limit_exceeded when it did not connect in time;
%          otherwise the error of tcp_connect/3.

timed_connect(Address, Pair, Timeout, Options) :-
    message_queue_create(Queue),
    catch(thread_create(connect_for(Queue, Address, Options), _, [detached(true)]),
          E, (message_queue_destroy(Queue), throw(E))),
    (   catch(thread_get_message(Queue, Reply, [timeout(Timeout)]), _, fail)
    ->  message_queue_destroy(Queue),
        answer(Reply, Pair)
    ;   with_mutex(dfrl_timed_connect, give_up(Queue)),
        throw(time_limit_exceeded)
    ).

answer(connected(Pair), Pair).
answer(failed(E), _) :-
    throw(E).

%   The waiting thread's side: take any reply that came in meanwhile (a
%   connection is closed) and remove the queue.
give_up(Queue) :-
    forall(catch(thread_get_message(Queue, connected(P), [timeout(0)]), _, fail),
           close(P, [force(true)])),
    message_queue_destroy(Queue).

connect_for(Queue, Address, Options) :-
    catch(tcp_connect(Address, Pair, Options), E, true),
    (   var(E)
    ->  Reply = connected(Pair)
    ;   Reply = failed(E)
    ),
    with_mutex(dfrl_timed_connect, hand_over(Queue, Reply)).

%   The connecting thread's side: the queue is gone when its waiter gave
%   up; a connection made too late is closed.
hand_over(Queue, Reply) :-
    (   catch(thread_send_message(Queue, Reply), _, fail)
    ->  true
    ;   Reply = connected(Pair)
    ->  close(Pair, [force(true)])
    ;   true
    ).
