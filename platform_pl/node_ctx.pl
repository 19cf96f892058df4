:- module(node_ctx,
          [ ctx_new/7,                  % +Node, +Peer, +Nonce, +In, +Out, +PeerName, -Ctx
            ctx_node/2,                 % +Ctx, -Node
            ctx_peer/2,                 % +Ctx, -Peer
            ctx_input/2,                % +Ctx, -InputStream
            ctx_output/2,               % +Ctx, -OutputStream
            ctx_nonce/2,                % +Ctx, -Nonce
            ctx_authenticated/1,        % +Ctx
            ctx_set_authenticated/2,    % +Ctx, +Bool
            ctx_peer_name/2             % +Ctx, -Name
          ]).

/** <module> The context of a connection a node serves

A node's connection worker (node_connection.pl) makes one context per
connection; request handlers (clauses of node:platform_request/4) read
it with the accessors here, which the module `node` re-exports. The
term is opaque to everyone else:

    ctx(Node, Peer, Nonce, In, Out, Authenticated, PeerName)

PeerName is the common name of the peer's verified TLS certificate, or
`none` on a plaintext connection. Authenticated is unbound until the
peer sent auth(Proofs), then `true` or `false`; it is set in place
(nb_setarg/3) by ctx_set_authenticated/2, so that the context the
worker keeps sees it.
*/

%!  ctx_new(+Node, +Peer, +Nonce, +In, +Out, +PeerName, -Ctx) is det.
%
%   Ctx is the context of a new connection of Node with Peer, greeted
%   with Nonce, on the streams In and Out; the peer has not tried to
%   authenticate yet.

ctx_new(Node, Peer, Nonce, In, Out, PeerName,
        ctx(Node, Peer, Nonce, In, Out, _Authenticated, PeerName)).

%!  ctx_node(+Ctx, -Node) is det.
%
%   Node is the platform that serves the connection.

ctx_node(ctx(Node, _, _, _, _, _, _), Node).

%!  ctx_peer(+Ctx, -Peer) is det.
%
%   Peer is the peer's address as tcp_accept/3 gave it.

ctx_peer(ctx(_, Peer, _, _, _, _, _), Peer).

%!  ctx_input(+Ctx, -In) is det.
%
%   In is the binary input stream of the connection (for a request that
%   reads further frames after its reply, as a staged migration does).

ctx_input(ctx(_, _, _, In, _, _, _), In).

%!  ctx_output(+Ctx, -Out) is det.
%
%   Out is the binary output stream of the connection.

ctx_output(ctx(_, _, _, _, Out, _, _), Out).

%!  ctx_nonce(+Ctx, -Nonce) is det.
%
%   Nonce is the one the node's hello sent: token proofs on this
%   connection are made for it.

ctx_nonce(ctx(_, _, Nonce, _, _, _, _), Nonce).

%!  ctx_authenticated(+Ctx) is semidet.
%
%   True if the peer proved one of the node's tokens on this connection.

ctx_authenticated(ctx(_, _, _, _, _, Auth, _)) :-
    Auth == true.

%   ctx_auth_tried(+Ctx): true if the peer sent auth(Proofs) on this
%   connection, whether or not a proof held.

ctx_auth_tried(ctx(_, _, _, _, _, Auth, _)) :-
    nonvar(Auth).

%!  ctx_set_authenticated(+Ctx, +Bool) is det.
%
%   Record in place whether the peer's last auth(Proofs) held. A
%   connection that authenticated once stays authenticated: a later
%   failed attempt does not undo it.

ctx_set_authenticated(Ctx, true) :-
    !,
    nb_setarg(6, Ctx, true).
ctx_set_authenticated(Ctx, false) :-
    (   ctx_auth_tried(Ctx)
    ->  true
    ;   nb_setarg(6, Ctx, false)
    ).

%!  ctx_peer_name(+Ctx, -Name) is semidet.
%
%   Name (an atom) is the common name of the certificate the peer
%   presented on this connection, verified against the node's CA (see
%   the tls(Dir) option of node_start/3). Fails on a plaintext
%   connection.

ctx_peer_name(ctx(_, _, _, _, _, _, Name), Name) :-
    atom(Name),
    Name \== none.
