:- module(bounds_peers,
          [ bounds_peer/2,              % +Ctx, -Peer
            bounds_peer/3,              % +Ctx, +Claim, -Peer
            bounds_peer_post/2          % +Ctx, +Link
          ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(node, [node_option/3, ctx_node/2, ctx_peer/2, ctx_peer_name/2]).
:- use_module(bounds_ledger,
              [ window_take/4, window_live/1, windows_prune/2, bounds_warning/2,
                stat_add/2 ]).

/** <module> Who a peer is, for the bounds per peer

The per-peer bounds of agent_bounds.pl (agents, run slots and posts of
one peer) need a name for the peer of a connection: what the connection
proves (a TLS certificate's name, else an IP address), and on plaintext
the node address the peer claims. This module names peers and counts the
posts a peer delivers (peer_post_limit).
*/

%!  bounds_peer(+Ctx, -Peer) is det.
%
%   Peer is what the connection Ctx proves of its peer: tls(Name), the
%   common name of its verified certificate, on a TLS connection; else
%   its IP address as tcp_accept/3 gave it (e.g. ip(127,0,0,1)), without
%   the port.

bounds_peer(Ctx, Peer) :-
    (   ctx_peer_name(Ctx, Name)
    ->  Peer = tls(Name)
    ;   ctx_peer(Ctx, Address),
        peer_host(Address, Host)
    ->  Peer = Host
    ;   Peer = unknown
    ).

peer_host(Host:_, Host) :- !.
peer_host(Host, Host) :- ground(Host).

%!  bounds_peer(+Ctx, +Claim, -Peer) is det.
%
%   Peer identifies the peer of Ctx for the per-peer bounds: tls(Name)
%   on a TLS connection (Claim is not used: the certificate says who it
%   is); on plaintext claim(IP, Address), its IP address and the node
%   address it claims (Claim: the source address of a transfer, the link
%   of a post; Host:Port or (Host,Port), else `none`). A plaintext peer
%   proves nothing but its IP address and a token, so every process on
%   one host (all robots of a loopback federation) has one IP: the
%   claimed address tells them apart, and is believed. A token holder
%   that claims many addresses gets many shares: the node-wide bounds
%   (max_agents, max_running_agents, the pool of posts) and the wall
%   and idle bounds still hold it; TLS gives names it cannot forge.

bounds_peer(Ctx, Claim, Peer) :-
    bounds_peer(Ctx, Peer0),
    (   Peer0 = tls(_)
    ->  Peer = Peer0
    ;   claimed_address(Claim, Address)
    ->  Peer = claim(Peer0, Address)
    ;   Peer = claim(Peer0, none)
    ).

claimed_address(Host:Port, Host:Port) :-
    short_atomic(Host),
    integer(Port),
    !.
claimed_address((Host, Port), Host:Port) :-
    short_atomic(Host),
    integer(Port).

%   At most 1024 peers of a node have a post window at a time.
max_post_peers(1024).

post_key(Node, Peer0, Peer) :-
    (   Peer0 = claim(IP, _),
        \+ window_live(peer_posts(Node, Peer0)),
        max_post_peers(Max),
        windows_prune(peer_posts(Node, _), Live),
        Live >= Max
    ->  Peer = claim(IP, many)
    ;   Peer = Peer0
    ).

short_atomic(X) :-
    atomic(X),
    \+ string(X),
    atom_length(X, L),
    L =< 255.

%!  bounds_peer_post(+Ctx, +Link) is det.
%
%   Count one post delivered from the peer of Ctx (bounds_peer/3, Link
%   the link the post carries, the sender's address by convention)
%   against the node's peer_post_limit(N) (per peer and minute). The
%   windows are kept for at most 1024 peers of a node at a time (those
%   of the last minute); a post from a peer beyond them counts for
%   claim(IP, many), shared by all such peers of its IP address.
%
%   @error resource_error(posts) if the peer delivered N posts this
%   minute already; such refusals are counted (bounds_statistics/1,
%   `refused_posts`) and a warning printed (rate-limited).

bounds_peer_post(Ctx, Link) :-
    ctx_node(Ctx, Node),
    node_option(Node, peer_post_limit, Max),
    (   Max == infinite
    ->  true
    ;   bounds_peer(Ctx, Link, Peer0),
        post_key(Node, Peer0, Peer),
        window_take(peer_posts(Node, Peer), Max, 1, Granted),
        (   Granted < 1
        ->  stat_add(refused_posts, 1),
            stat_add(refused_posts(Node), 1),
            bounds_warning(Node, dfrl_bounds(refused_posts(Node, Peer, Max))),
            throw(error(resource_error(posts), context(_, peer_limit(Max))))
        ;   true
        )
    ).
