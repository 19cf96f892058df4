:- module(node_admission,
          [ admission_admit/5,          % +Node, +ConnId, +PeerKey, +Limits, -Verdict
            admission_holds/2,          % +Node, +ConnId
            admission_authenticated/2,  % +Node, +ConnId
            admission_forget/2,         % +Node, +ConnId
            admission_forget_node/1     % +Node
          ]).
:- autoload(library(aggregate), [aggregate_all/3]).
:- autoload(library(lists), [member/2]).

/** <module> Which connections a node admits, and which it evicts

Every connection a node accepts starts unauthenticated and becomes
authenticated when its peer proves a token; this module keeps each
connection's class. Unauthenticated connections are capped per peer
address and in total, below the node's max_connections, so the
remaining slots are kept for authenticated ones, which an
unauthenticated flood never displaces. At a cap the new connection is
not refused: the oldest unauthenticated connection of the same peer
(per-peer cap) or of the peer holding the most (total cap) is evicted,
so a trickling or idle peer cannot keep a newcomer out, and a newcomer
that proves its token at once becomes authenticated before its turn
comes. Only when every slot is authenticated is a connection refused.

All state changes run under the mutex `dfrl_conns`, so the acceptor
and the connection workers of every node of the process see one
consistent count.
*/

:- dynamic
    conn_entry/5.               % Node, ConnId, PeerKey, Class, Since

%!  admission_admit(+Node, +ConnId, +PeerKey, +Limits, -Verdict) is det.
%
%   Decide on the new connection ConnId of Node from the peer PeerKey
%   (its address without the port). Limits is limits(Max, MaxUnauth,
%   MaxPerPeer): the node's max_connections, max_unauth_connections and
%   max_unauth_per_peer. Verdict is `admit`, evict(Victim) (ConnId is
%   admitted and the connection Victim no longer counts: its worker must
%   be told to close it) or `refuse` (ConnId is not recorded).

admission_admit(Node, CId, Key, Limits, Verdict) :-
    get_time(Now),
    with_mutex(dfrl_conns, admit(Node, CId, Key, Now, Limits, Verdict)).

admit(Node, CId, Key, Now, limits(Max, MaxU, MaxP), Verdict) :-
    aggregate_all(count, conn_entry(Node, _, _, _, _), Total),
    aggregate_all(count, conn_entry(Node, _, _, unauth, _), Unauth),
    aggregate_all(count, conn_entry(Node, _, Key, unauth, _), Mine),
    (   Mine >= MaxP
    ->  oldest_unauth(Node, Key, Victim),
        Verdict = evict(Victim)
    ;   Unauth >= MaxU
    ->  busiest_peer(Node, Busiest),
        oldest_unauth(Node, Busiest, Victim),
        Verdict = evict(Victim)
    ;   Total >= Max
    ->  (   busiest_peer(Node, Busiest)
        ->  oldest_unauth(Node, Busiest, Victim),
            Verdict = evict(Victim)
        ;   Verdict = refuse
        )
    ;   Verdict = admit
    ),
    (   Verdict = evict(V)
    ->  retractall(conn_entry(Node, V, _, _, _))
    ;   true
    ),
    (   Verdict == refuse
    ->  true
    ;   assertz(conn_entry(Node, CId, Key, unauth, Now))
    ).

oldest_unauth(Node, Key, Victim) :-
    aggregate_all(min(Since, C), conn_entry(Node, C, Key, unauth, Since),
                  min(_, Victim)).

busiest_peer(Node, Key) :-
    findall(K, conn_entry(Node, _, K, unauth, _), Ks),
    Ks \== [],
    msort(Ks, Sorted),
    clumped_pairs(Sorted, Counts),
    aggregate_all(max(N, K), member(K-N, Counts), max(_, Key)).

clumped_pairs([], []).
clumped_pairs([K|Ks], [K-N|Rest]) :-
    take_same(K, Ks, 1, N, Ks1),
    clumped_pairs(Ks1, Rest).

take_same(K, [K1|Ks], N0, N, Rest) :-
    K1 == K,
    !,
    N1 is N0 + 1,
    take_same(K, Ks, N1, N, Rest).
take_same(_, Ks, N, N, Ks).

%!  admission_holds(+Node, +ConnId) is semidet.
%
%   True if ConnId still counts as a connection of Node (it was admitted
%   and not evicted or forgotten since).

admission_holds(Node, CId) :-
    conn_entry(Node, CId, _, _, _),
    !.

%!  admission_authenticated(+Node, +ConnId) is det.
%
%   The peer of ConnId proved a token: the connection no longer counts
%   against the unauthenticated caps (and is never evicted). Nothing
%   happens if it was evicted already.

admission_authenticated(Node, CId) :-
    with_mutex(dfrl_conns,
               (   retract(conn_entry(Node, CId, Key, _, Since))
               ->  assertz(conn_entry(Node, CId, Key, auth, Since))
               ;   true
               )).

%!  admission_forget(+Node, +ConnId) is det.
%
%   ConnId of Node has ended (or could not be served).

admission_forget(Node, CId) :-
    with_mutex(dfrl_conns, retractall(conn_entry(Node, CId, _, _, _))).

%!  admission_forget_node(+Node) is det.
%
%   Node has stopped: forget all its connections.

admission_forget_node(Node) :-
    with_mutex(dfrl_conns, retractall(conn_entry(Node, _, _, _, _))).
