:- module(bounds_slots,
          [ slot_hold/2,                % +Node, +Agent
            slot_release/0,
            slot_park/0,
            slot_unpark/2,              % +Node, +Agent
            slots_sweep_peers/0
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(lists), [member/2]).
:- use_module(node, [node_option/3]).
:- use_module(bounds_ledger, [bounds_warning/2, stat_add/2]).

/** <module> Run slots: how many agent calls run at once

The bounds max_running_agents(N) and max_running_per_peer(P) of
agent_bounds.pl: a bounded call holds a slot of its node, and one of its
peer's, while it runs; a call that waits (bounds_park/1) gives them back
meanwhile. The slot a call holds is kept thread-locally.
*/

:- dynamic
    slot_queue_/2,              % Node or Node-Peer, Queue of its tokens
    queues_swept_/1.            % Time of the last sweep of peer queues

:- thread_local
    held_slot_/1.               % Slot: the run slot this thread's call holds

:- multifile
    node:node_stopping/1.

%!  slot_hold(+Node, +Agent) is det.
%!  slot_release is det.
%
%   Take a run slot for a call of Agent on Node (waiting for one), and
%   give it back.
%
%   max_running_agents(N): a call takes one of N slots of its node (a
%   message queue holding N tokens) before it starts, and waits for one
%   when all are taken, at most agent_slot_wait(Sec) (node option, 60).
%   Waiting costs no CPU and is not counted in the call's bounds.
%   max_running_per_peer(P): a call of an agent that arrived from a peer
%   first takes one of that peer's P slots (a queue per node and peer),
%   so that one peer's calls never hold more than P of the N slots and
%   another peer's call finds one free. Both waits together take at
%   most agent_slot_wait. The slot held is kept thread-locally, so that
%   bounds_park/1 can give it back while the call waits.

slot_hold(Node, Agent) :-
    retractall(held_slot_(_)),
    take_slot(Node, Agent, Slot),
    assertz(held_slot_(Slot)).

slot_release :-
    (   retract(held_slot_(Slot))
    ->  give_slot(Slot)
    ;   true
    ).

take_slot(Node, Agent, Slot) :-
    node_option(Node, max_running_agents, Max),
    node_option(Node, agent_slot_wait, Wait),
    get_time(T0),
    Deadline is T0 + Wait,
    agent_peer(Node, Agent, Peer),
    node_option(Node, max_running_per_peer, PeerMax),
    (   ( Peer == local ; PeerMax == infinite )
    ->  PeerSlot = none
    ;   slot_queue(Node-Peer, PeerMax, PeerQueue),
        (   wait_token(PeerQueue, Deadline)
        ->  PeerSlot = PeerQueue
        ;   bounds_warning(Node, dfrl_bounds(no_slot(Node, Agent, PeerMax, Wait))),
            throw(error(resource_error(running_agents), context(_, peer_limit(PeerMax))))
        )
    ),
    (   Max == infinite
    ->  Slot = slot(none, PeerSlot)
    ;   slot_queue(Node, Max, Queue),
        (   wait_token(Queue, Deadline)
        ->  Slot = slot(Queue, PeerSlot)
        ;   give_slot(slot(none, PeerSlot)),
            bounds_warning(Node, dfrl_bounds(no_slot(Node, Agent, Max, Wait))),
            throw(error(resource_error(running_agents), context(_, limit(Max))))
        )
    ).

wait_token(Queue, Deadline) :-
    (   thread_get_message(Queue, slot, [timeout(0)])
    ->  true
    ;   stat_add(slot_waits, 1),
        get_time(Now),
        Left is max(0, Deadline - Now),
        thread_get_message(Queue, slot, [timeout(Left)])
    ).

give_slot(none).
give_slot(parked).
give_slot(slot(Queue, PeerQueue)) :-
    give_token(PeerQueue),
    give_token(Queue).

give_token(none) :- !.
give_token(Queue) :-
    catch(thread_send_message(Queue, slot), _, true).

%   The queue of the slots of Key (a node, or Node-Peer), made with Max
%   tokens on first use.
slot_queue(Key, Max, Queue) :-
    (   slot_queue_(Key, Q0)
    ->  Queue = Q0
    ;   with_mutex(dfrl_bounds_monitor,
                   (   slot_queue_(Key, Q0)
                   ->  Queue = Q0
                   ;   message_queue_create(Queue),
                       forall(between(1, Max, _), thread_send_message(Queue, slot)),
                       assertz(slot_queue_(Key, Queue))
                   ))
    ).

%   The peer an agent arrived from (agents.pl keeps it), `local` for an
%   agent made here, or one that is gone.
agent_peer(Node, Agent, Peer) :-
    (   agents:agent_property(Node, Agent, peer(P))
    ->  Peer = P
    ;   Peer = local
    ).

%!  slot_park is semidet.
%
%   Give back the slot this thread's call holds, the call still
%   running: it waits (bounds_park/1). Fails if it holds none or has
%   parked already.

slot_park :-
    held_slot_(Slot),
    Slot \== parked,
    retractall(held_slot_(_)),
    assertz(held_slot_(parked)),
    give_slot(Slot).

%!  slot_unpark(+Node, +Agent) is det.
%
%   Take a slot again after slot_park/0 (waiting, parked, up to twice
%   agent_slot_wait).
%
%   @error resource_error(running_agents) if none came.

slot_unpark(Node, Agent) :-
    retractall(held_slot_(_)),              % waiting for a slot is parked
    retake_slot(Node, Agent, Slot),
    assertz(held_slot_(Slot)).

%   A parked call waits for a slot twice as long as a new one (two
%   agent_slot_wait): it has run already, and giving up costs its work.
retake_slot(Node, Agent, Slot) :-
    catch(take_slot(Node, Agent, Slot), error(resource_error(running_agents), _), fail),
    !.
retake_slot(Node, Agent, Slot) :-
    take_slot(Node, Agent, Slot).

%!  slots_sweep_peers is det.
%
%   The slot queue of a peer that has no agent left on its node, and
%   whose tokens are all back, is destroyed (at most every 10 s): a
%   plaintext peer may claim a new address with every agent it sends.

slots_sweep_peers :-
    get_time(Now),
    (   queues_swept_(T), Now - T < 10
    ->  true
    ;   retractall(queues_swept_(_)),
        assertz(queues_swept_(Now)),
        with_mutex(dfrl_bounds_monitor,
                   findall(Q,
                           ( slot_queue_(Node-Peer, Q),
                             \+ agents:agent_property(Node, _, peer(Peer)),
                             catch(node_option(Node, max_running_per_peer, Max), _, fail),
                             integer(Max),
                             message_queue_property(Q, size(Max)),
                             retract(slot_queue_(Node-Peer, Q)) ),
                           Qs)),
        forall(member(Q, Qs), catch(message_queue_destroy(Q), _, true))
    ).

node:node_stopping(Node) :-
    with_mutex(dfrl_bounds_monitor,
               findall(Queue,
                       ( slot_queue_(Key, Queue),
                         ( Key == Node ; Key = Node-_ ),
                         retract(slot_queue_(Key, Queue)) ),
                       Queues)),
    forall(member(Queue, Queues),
           catch(message_queue_destroy(Queue), _, true)).
